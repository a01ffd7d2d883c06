"""Today's code repeats the records fixture (`tests/learner/records.py`): each method's
short seeded run takes the recorded actions from the recorded sources, gets the recorded
rewards, outcomes and images, and computes the recorded Q-values and losses."""

from __future__ import annotations

import dataclasses
import math

import pytest

from learner.machine import cpu_kind
from tests.learner import records


@pytest.mark.parametrize("method", records.METHODS)
def test_a_run_repeats_its_recorded_steps(method: str) -> None:
    kind = cpu_kind()
    own = records.has_own(kind) or kind == records.REFERENCE_KIND
    recorded = records.read(method, kind if own else records.REFERENCE_KIND)
    steps = [dataclasses.asdict(s) for s in records.run(method)]
    assert len(steps) == len(recorded)
    if not own:
        # A CPU kind without records of its own: the same course up to the first step at
        # which its float32 ranks the learner's actions differently, never before training.
        _same_course_until_the_ranking_differs(method, kind, steps, recorded)
        return
    for now, then in zip(steps, recorded, strict=True):
        where = f"{method}, step {then['global_step']} ({kind})"
        assert {k: now[k] for k in records.EXACT} == {k: then[k] for k in records.EXACT}, where
        for name in records.CLOSE:
            if then[name] is None:
                assert now[name] is None, (where, name)
            else:
                assert math.isclose(now[name], then[name], rel_tol=1e-5, abs_tol=1e-7), (
                    where,
                    name,
                    now[name],
                    then[name],
                )


def test_the_fixture_covers_advice_from_every_source() -> None:
    sources = {m: {row["action_source"] for row in records.read(m)} for m in records.METHODS}
    assert "advisor" not in sources["autonomous"]
    for method in ("agent", "oracle", "replayed"):
        assert "advisor" in sources[method], method
    rows = records.read("replayed")
    advised = [r["advised_action"] for r in rows if r["advised_action"] is not None]
    assert advised == records.STREAM
    assert {"greedy", "exploration", "random"} <= sources["autonomous"]


def _same_course_until_the_ranking_differs(
    method: str, kind: str, steps: list[dict], recorded: list[dict]
) -> None:
    where = f"(the records were checked on {records.checked_kinds()}, never on {kind})"
    for now, then in zip(steps, recorded, strict=True):
        if now["greedy_action"] != then["greedy_action"]:
            assert then["stage"] == "train", (method, then["global_step"], where)
            return
        for name in records.EXACT:
            assert now[name] == then[name], (method, then["global_step"], name, where)
