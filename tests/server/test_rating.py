"""A person's evaluative feedback through the participant endpoints, as the page gives it:
each turn shows the action the learner took and takes a rating within the run's time-out;
a rating outside that window is refused, a turn left alone is recorded as no answer, and
the export's feedback rows hold every turn with both times."""

from __future__ import annotations

import csv
import io
import time
from typing import Any

import httpx
import pytest

from tests.server.live import LiveServer
from tests.server.participant import SimulatedParticipant
from tests.server.scale import export, session_body, wait_for_status

pytestmark = pytest.mark.slow
BUDGET = 4
TIME_OUT_S = 1.5
SIDES = {"red": "left", "blue": "right"}
"""The colour rule, the sessions' (blue right, red left)."""


def sorted_by_colour(state: dict[str, Any]) -> int:
    """The sorting robot's correct action by hand, from what the turn's state says the arm
    holds and where: grab when it holds nothing, drop at the held object's side, else move
    towards it (0 grab, 1 move right, 2 move left, 3 drop)."""
    if state["held"] is None:
        return 0
    side = SIDES[state["held"]["color"]]
    if state["station"] == side:
        return 3
    return 1 if side == "right" else 2


@pytest.mark.parametrize("task", ["gridworld", "sorting"])
def test_ratings_are_taken_in_their_window_and_a_silent_turn_is_recorded_as_none(
    server: LiveServer, api: httpx.Client, task: str
) -> None:
    study = api.post("/api/studies", json={"name": f"human ratings {task}"}).json()
    body = session_body(
        "human",
        task=task,
        advice_budget=BUDGET,
        feedback="evaluative",
        feedback_weight=0.5,
        rating_time_out_s=TIME_OUT_S,
    )
    created = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
    assert created["run"]["rating_time_out_s"] == TIME_OUT_S, created
    participant = SimulatedParticipant(server.url, created["participant_token"])
    early = participant.client.post(
        "/api/participant/rating", json={"advice_index": 0, "rating": "good"}
    )
    assert early.status_code == 409, early.text
    assert participant.begin().status_code == 200

    shown: list[tuple[int, float, float]] = []  # index, our clock from showing to receipt
    correct: list[int] = []  # the sorting task's correct action at each rated step, by hand
    for index, rating in enumerate(["good", None, "bad", "good"]):
        state = participant.next_request()
        seen = time.monotonic()
        if task == "sorting":
            correct.append(sorted_by_colour(state))
        assert state["advice_index"] == index and state["rated_action"] in range(4), state
        assert 0 < state["rating_left_s"] <= TIME_OUT_S
        advice = participant.advise(index, 0)
        assert advice.status_code == 409 and "asks for a rating" in advice.text
        wrong = participant.client.post(
            "/api/participant/rating", json={"advice_index": index + 1, "rating": "good"}
        )
        assert wrong.status_code == 409 and f"turn {index} is to be rated" in wrong.text
        bad = participant.client.post(
            "/api/participant/rating", json={"advice_index": index, "rating": "maybe"}
        )
        assert bad.status_code == 422, bad.text
        if rating is None:
            time.sleep(TIME_OUT_S + 0.5)
            late = participant.client.post(
                "/api/participant/rating", json={"advice_index": index, "rating": "good"}
            )
            assert late.status_code == 409, late.text
            assert "no answer" in late.text or "is over" in late.text
            continue
        sent = time.monotonic()
        receipt = participant.client.post(
            "/api/participant/rating",
            json={"advice_index": index, "rating": rating, "decision_time_s": 0.25 + index},
        )
        back = time.monotonic()
        assert receipt.status_code == 200, receipt.text
        got = receipt.json()
        assert got["judgement"] == (1.0 if rating == "good" else -1.0)
        assert got["shaping"] == 0.5 * got["judgement"] and got["duplicate"] is False
        assert got["action"] == state["rated_action"]
        shown.append((index, back - seen, back - sent))
        again = participant.client.post(
            "/api/participant/rating", json={"advice_index": index, "rating": rating}
        )
        assert again.status_code == 200 and again.json()["duplicate"] is True
        flip = "bad" if rating == "good" else "good"
        changed = participant.client.post(
            "/api/participant/rating", json={"advice_index": index, "rating": flip}
        )
        assert changed.status_code == 409 and "cannot be changed" in changed.text

    over = participant.client.post(
        "/api/participant/rating", json={"advice_index": BUDGET, "rating": "good"}
    )
    assert over.status_code == 409, over.text
    wait_for_status(api, created["id"], {"finished"})

    files = export(api, study["id"])
    rows = list(csv.DictReader(io.StringIO(files["feedback.csv"].decode())))
    rows = [r for r in rows if r["session_id"] == str(created["id"])]
    assert [r["feedback_index"] for r in rows] == ["0", "1", "2", "3"]
    assert [r["evaluator"] for r in rows] == ["human"] * BUDGET
    assert [r["judgement"] for r in rows] == ["1.0", "", "-1.0", "1.0"]
    assert [r["shaping"] for r in rows] == ["0.5", "0.0", "-0.5", "0.5"]
    assert [r["decision_time_s"] for r in rows] == ["0.25", "", "2.25", "3.25"]
    assert TIME_OUT_S - 0.5 < float(rows[1]["response_time_s"]) <= TIME_OUT_S + 0.5  # its time-out
    for index, ours, round_trip in shown:
        server_s = float(rows[index]["response_time_s"])
        assert server_s <= ours + 0.05, (index, server_s, ours)
        assert server_s >= ours - round_trip - 0.05, (index, server_s, ours, round_trip)
    assert all(len(r["observation_hash"]) == 16 for r in rows)
    if task == "sorting":  # the arm's state at the rated step, before its action was taken
        assert [int(r["correct_action"]) for r in rows] == correct
    else:  # the grid world's shortest path: its next move, one of the four
        assert all(r["correct_action"] in ("0", "1", "2", "3") for r in rows), rows
    participant.close()


def test_a_pause_stops_a_ratings_clock_and_gives_it_a_whole_time_out_after(
    server: LiveServer, api: httpx.Client
) -> None:
    study = api.post("/api/studies", json={"name": "paused rating"}).json()
    body = session_body("human", task="gridworld", advice_budget=2, feedback="evaluative",
                        rating_time_out_s=TIME_OUT_S)  # fmt: skip
    created = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
    participant = SimulatedParticipant(server.url, created["participant_token"])
    assert participant.begin().status_code == 200
    state = participant.next_request()
    assert state["advice_index"] == 0 and state["rated_action"] is not None
    assert api.post(f"/api/sessions/{created['id']}/pause").status_code == 200
    time.sleep(TIME_OUT_S + 1.0)
    paused = participant.client.post(
        "/api/participant/rating", json={"advice_index": 0, "rating": "good"}
    )
    assert paused.status_code == 409 and "paused" in paused.text
    assert api.post(f"/api/sessions/{created['id']}/resume").status_code == 200
    time.sleep(0.5)
    state = participant.state()
    assert state["advice_index"] == 0 and state["rating_left_s"] > 0.2, state
    rated = participant.client.post(
        "/api/participant/rating", json={"advice_index": 0, "rating": "good"}
    )
    assert rated.status_code == 200, rated.text
    participant.close()


def test_turns_that_lapse_for_the_idle_limit_abandon_the_session(
    server: LiveServer, api: httpx.Client
) -> None:
    """A person who stops rating is gone once the turns that lapsed one after another add up
    to the idle limit: the session is abandoned (as an advice session without advice is),
    while a rating in between starts the count again."""
    study = api.post("/api/studies", json={"name": "a rater who leaves"}).json()
    body = session_body("human", task="gridworld", advice_budget=8, feedback="evaluative",
                        rating_time_out_s=1.0, idle_limit_s=2.5)  # fmt: skip
    created = api.post(f"/api/studies/{study['id']}/sessions", json=body).json()
    participant = SimulatedParticipant(server.url, created["participant_token"])
    assert participant.begin().status_code == 200
    for index, rating in enumerate(["good", None, "bad", None, None]):
        state = participant.next_request()
        assert state["advice_index"] == index, state
        if rating is not None:
            sent = participant.client.post(
                "/api/participant/rating", json={"advice_index": index, "rating": rating}
            )
            assert sent.status_code == 200, sent.text
    final = wait_for_status(api, created["id"], {"abandoned", "finished"})
    assert final["status"] == "abandoned", final
    assert "no rating" in (final.get("status_detail") or ""), final

    files = export(api, study["id"])
    rows = list(csv.DictReader(io.StringIO(files["feedback.csv"].decode())))
    rows = [r for r in rows if r["session_id"] == str(created["id"])]
    assert [r["judgement"] for r in rows] == ["1.0", "", "-1.0", "", "", ""]
    participant.close()
