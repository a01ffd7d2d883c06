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
    "episodes": "Training episodes the session was set to run [count].",
    "max_episode_steps": "Steps after which an episode is truncated [count].",
    "config": "The full learner configuration, as JSON.",
    "status": "Final or current status (finished, running, stopped, interrupted, ...).",
    "created_at": "When the session was created [UTC, ISO 8601].",
    "started_at": "When it first started [UTC, ISO 8601].",
    "finished_at": "When it finished [UTC, ISO 8601].",
    "texts_version": "Version of the study's texts the participant was shown when they "
    "consented or declined (texts_versions.csv has them); empty for machine sessions.",
    "consented_at": "When the participant consented, recorded by the server; no advice is "
    "asked before it [UTC, ISO 8601].",
    "declined_at": "When the participant last declined (they may consent later) [UTC, ISO 8601].",
    "induction_done_at": "When the participant finished the three-step induction (pressed "
    "Start); advice is asked only after it [UTC, ISO 8601].",
}
TEXTS_COLUMNS = {
    "study_id": "Study the texts belong to.",
    "texts_version": "Version number within the study, from 1; a new version is stored "
    "whenever the texts shown change (e.g. edited after sessions ran).",
    "content_hash": "SHA-256 of the version's texts (JSON, sorted keys).",
    "created_at": "When this version was first shown [UTC, ISO 8601].",
    "title": "Page title, exactly as shown.",
    "consent": "Consent text, exactly as shown (placeholders filled in; plain text with "
    "## headings, - bullets, **bold**).",
    "induction_1": "Induction step 1 (the scenario and expected results), as shown.",
    "induction_2": "Induction step 2 (the problem and how to solve it), as shown.",
    "induction_3": "Induction step 3 (how to use the interface), as shown.",
    "thanks": "Thank-you page text, as shown.",
}
ADVICE_COLUMNS = {
    "session_id": "Session the advice belongs to.",
    "advice_index": "Index of the advice in its session, from 0 [count].",
    "global_step": "Global step the advice was for (from 1, pretraining included).",
    "advisor": "Who advised: human, agent, oracle or random.",
    "action": "Advised action: 0 grab, 1 move right, 2 move left, 3 drop.",
    "action_name": "The advised action's name.",
    "greedy_action": "The learner's own greedy choice for the same observation (if known).",
    "response_time_s": "Server side: time from the page first reading the request to the "
    "advice arriving [s]; for people this includes the 3-D replay of the robot's last move "
    "(buttons still off) and network time. For machine advisors: the advisor's compute time.",
    "decision_time_s": "Browser side (people only): time from the action buttons becoming "
    "active to the click or key, on the browser's monotonic clock (performance.now()) [s]; "
    "the participant's own decision time. Empty for machine advisors.",
    "requested_at": "Server side: when the page first read the request [UTC, ISO 8601].",
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
    docs = {
        "sessions.csv": SESSION_COLUMNS,
        "advice.csv": ADVICE_COLUMNS,
        "texts_versions.csv": TEXTS_COLUMNS,
        **record_columns(),
    }
    rows = []
    for name, columns in files.items():
        for column in columns:
            description = docs.get(name, {}).get(column) or "(not documented)"
            rows.append({"file": name, "column": column, "description": description})
    return rows
