"""The export's column dictionary: what each column means and its unit.

Step and episode columns are documented where they are made, in the docstrings under the
learner's `StepRecord` and `EpisodeRecord` fields; the rest are documented here."""

from __future__ import annotations

import ast
import inspect
import itertools
import textwrap
from typing import Any

SESSION_COLUMNS = {
    "session_id": "Session id (unique in the database).",
    "study_id": "Study the session belongs to.",
    "label": "Free text set by the researcher (e.g. a batch name).",
    "method": "Who advised: autonomous, agent, human, oracle or random.",
    "participant": "Pseudonym of the human advisor (human sessions).",
    "seed": "Seed of the scene, network init, memory sampling and exploration.",
    "strategy": "Advising strategy (early, alternating, importance, mistake_correcting).",
    "advice_budget": "Advice the strategy may ask for in all [count].",
    "advisor_checkpoint": "Trained learner that advised (agent sessions).",
    "oracle_error_rate": "Chance the oracle advised a wrong action (oracle sessions) [0-1].",
    "motion": "physics (simulated motion) or fast (poses set directly).",
    "sort_rule": "Sorting rule, as JSON (color, shape, or a map object -> side).",
    "reward_scheme": "What a step without a placement cost: paper (-0.01 after the 18th "
    "step), authors-autonomous (0 up to the 19th, then -0.01 x (n - 19)), authors-interactive "
    "(-0.01 from the first step).",
    "grasp_failure_rate": "Chance that a grab came back empty (realism option) [0-1].",
    "knock_off_rate": "Chance that a grab knocked another object off the center table [0-1].",
    "episodes": "Training episodes the session was set to run [count].",
    "max_episode_steps": "Steps after which an episode is truncated [count].",
    "config": "The full learner configuration, as JSON.",
    "status": "Final or current status (finished, running, stopped, interrupted, ...).",
    "created_at": "When the session was created [UTC, ISO 8601].",
    "started_at": "When it first started [UTC, ISO 8601].",
    "finished_at": "When it finished [UTC, ISO 8601].",
}
ADVICE_COLUMNS = {
    "session_id": "Session the advice belongs to.",
    "advice_index": "Index of the advice in its session, from 0 [count].",
    "global_step": "Global step the advice was for (from 1, pretraining included).",
    "advisor": "Who advised: human, agent, oracle or random.",
    "action": "Advised action: 0 grab, 1 move right, 2 move left, 3 drop.",
    "action_name": "The advised action's name.",
    "greedy_action": "The learner's own greedy choice for the same observation (if known).",
    "response_time_s": "Time from showing the observation to receiving the advice [s]; "
    "for people measured by the server, so network time is included.",
    "requested_at": "When the observation was shown [UTC, ISO 8601].",
    "answered_at": "When the advice arrived [UTC, ISO 8601].",
    "observation_file": "PNG (64x64 RGB, lossless) of what the advisor saw, in advice/.",
}
SESSION_KEY = {
    "session_id": "Session the record belongs to.",
    "wall_time": "When the session's worker logged the record [Unix time, s].",
}


def field_docs(cls: type) -> dict[str, str]:
    """Docstrings written under the fields of a (data)class, by field name."""
    try:
        source = textwrap.dedent(inspect.getsource(cls))
    except (OSError, TypeError):
        return {}
    tree = ast.parse(source)
    klass = tree.body[0]
    assert isinstance(klass, ast.ClassDef)
    docs: dict[str, str] = {}
    body = klass.body
    for node, following in itertools.pairwise(body):
        if (
            isinstance(node, ast.AnnAssign)
            and isinstance(node.target, ast.Name)
            and isinstance(following, ast.Expr)
            and isinstance(following.value, ast.Constant)
            and isinstance(following.value.value, str)
        ):
            docs[node.target.id] = " ".join(following.value.value.split())
    return docs


def record_columns() -> dict[str, dict[str, str]]:
    """Step and episode column docs, from the learner's record classes."""
    from learner import EpisodeRecord, StepRecord

    return {
        "steps.csv": {**SESSION_KEY, **field_docs(StepRecord)},
        "episodes.csv": {**SESSION_KEY, **field_docs(EpisodeRecord)},
    }


def column_dictionary(files: dict[str, list[str]]) -> list[dict[str, Any]]:
    """Rows (file, column, description) for every column of every exported file."""
    docs = {"sessions.csv": SESSION_COLUMNS, "advice.csv": ADVICE_COLUMNS, **record_columns()}
    rows = []
    for name, columns in files.items():
        for column in columns:
            description = docs.get(name, {}).get(column) or "(not documented)"
            rows.append({"file": name, "column": column, "description": description})
    return rows
