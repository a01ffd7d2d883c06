"""An online visit to a task other than the sorting robot's (the grid world): the pages
speak of its agent, its goal, its actions and keys, never of the robot, its tables or its
four actions; the design's default check asks the task's own questions, graded by their
right answers; the sorting robot's pages keep their own texts."""

from __future__ import annotations

import re
from typing import Any

import httpx
import pytest

from study.schemas.design import Condition, StudyDesign
from tasks import get_task
from tasks.sorting import TEXTS
from tests.server.live import LiveServer
from tests.server.participant import SimulatedParticipant
from tests.server.scale import session_body
from tests.study.test_visit import set_design

pytestmark = pytest.mark.slow

SORTING_ONLY = ("robot", "table", "Grab", "sorting rule", "cube")
"""Words of the sorting robot's pages that another task's must not show."""


def _participant(
    server: LiveServer, api: httpx.Client, study_id: int, **run: Any
) -> tuple[dict[str, Any], SimulatedParticipant]:
    body = session_body("human", **{"advice_budget": 2, **run})
    created = api.post(f"/api/studies/{study_id}/sessions", json=body)
    assert created.status_code == 201, created.text
    made = created.json()
    return made, SimulatedParticipant(server.url, made["participant_token"])


def _text(html: str) -> str:
    """The page's main text, without its tags and its scripts."""
    main = html.split("<main", 1)[-1]
    return re.sub(r"<[^>]+>", " ", re.sub(r"<script.*?</script>", "", main, flags=re.S))


def test_a_grid_world_visit_speaks_of_its_task_and_asks_its_own_check(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": "grid world texts"}).json()
    design = StudyDesign(conditions={"a": Condition(run={"method": "human", "task": "gridworld"})})
    set_design(server, study["id"], design.model_dump(mode="json"))
    created, participant = _participant(server, api, study["id"], task="gridworld", motion=None)
    page = f"{server.url}/p/{created['participant_token']}"
    try:
        consent = httpx.get(f"{page}/consent", timeout=60).text
        assert "· Help an agent learn: Grid world</title>" in consent, consent[:400]
        participant.consent()
        task = get_task("gridworld")
        pages = {
            step: _text(httpx.get(f"{page}/induction/{step}", timeout=60).text)
            for step in (1, 2, 3)
        }
        assert task.goal in pages[1] and "The agent and the experiment" in pages[1]
        for word in ("Up", "Right", "Down", "Left"):
            assert word in pages[2], (word, pages[2])
        assert "↑ up" in pages[3].replace("  ", " ") or "↑" in pages[3], pages[3]
        for text in (_text(consent), *pages.values()):
            for word in SORTING_ONLY:
                assert word not in text, (word, text)

        shown = participant.client.get("/api/participant/check").json()
        assert [q["id"] for q in shown["questions"]] == [q.id for q in task.check_questions]
        labels = [c["label"] for c in shown["questions"][0]["choices"]]
        assert labels == list(task.check_questions[0].choices)
        right = {q.id: "abcdefgh"[q.choices.index(q.answer)] for q in task.check_questions}
        wrong = {**right, "gridworld_goal": "b"}
        graded = participant.client.post("/api/participant/check", json={"answers": wrong})
        assert graded.json()["wrong"] == ["gridworld_goal"], graded.text
        passed = participant.client.post("/api/participant/check", json={"answers": right})
        assert passed.json()["passed"], passed.text
    finally:
        participant.client.close()
        api.post(f"/api/sessions/{created['id']}/stop")


def test_the_sorting_robots_pages_keep_their_own_texts(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": "robot texts"}).json()
    created, participant = _participant(server, api, study["id"])
    page = f"{server.url}/p/{created['participant_token']}"
    try:
        consent = httpx.get(f"{page}/consent", timeout=60).text
        assert "· Help a robot learn to sort</title>" in consent
        participant.consent()
        second = httpx.get(f"{page}/induction/2").text
        assert "The robot and the experiment" in second
        first_line = (TEXTS / "induction_2.txt").read_text().splitlines()[0].lstrip("# ")
        assert first_line in second, first_line
        assert "Grab" in second and "Move right" in second
    finally:
        participant.client.close()
        api.post(f"/api/sessions/{created['id']}/stop")
