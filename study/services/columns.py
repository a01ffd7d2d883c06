"""The export's column dictionary: each column's type, unit and meaning.

Step and episode columns are documented where they are made, in the docstrings under the
learner's `StepRecord` and `EpisodeRecord` fields (their types come from the database
model), but for the steps' Q-values: one `q_<action>` column per action of the exported
sessions' tasks (`QActions`), named by the task (`tasks.Task.action_names`). The run's
columns (method, seed, config_*, strategy_*, scenario options, ...) come from
the run's declaration (`learner.run.RunSpec`, its docstrings and ranges); the rest are
documented here."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from learner.docstrings import field_docstrings
from learner.fields import leaves
from learner.records import STORED_Q, EpisodeRecord, StepRecord
from learner.run import declared
from study.services.tables import Column, column
from study.services.visit_export import VISIT_COLUMNS
from tasks import Task, get_task


@dataclass(frozen=True)
class QActions:
    """A task's actions as the export's Q-value columns name them."""

    names: tuple[str, ...]
    """Each action's name, in the learner's order (`tasks.Task.action_names`)."""
    words: tuple[str, ...]
    """Each action's words, as its task's page shows them."""

    @classmethod
    def of(cls, task: Task) -> QActions:
        return cls(task.action_names, task.action_words)

    @classmethod
    def numbered(cls, count: int) -> QActions:
        """A task the exporting process cannot load (a researcher's module it cannot
        import): its actions by their index."""
        names = tuple(f"action_{i}" for i in range(count))
        return cls(names, names)

    @property
    def columns(self) -> tuple[str, ...]:
        return tuple(f"q_{name}" for name in self.names)


SESSION_COLUMNS: dict[str, tuple[str, str]] = {
    "session_id": ("integer", "Session id (unique in the database)."),
    "study_id": ("integer", "Study the session belongs to."),
    "label": ("string", "Free text set by the researcher (e.g. a batch name)."),
    "participant": ("string", "Pseudonym of the human advisor (human sessions)."),
    "status": ("string", "Final or current status (finished, running, stopped, ...)."),
    "created_at": ("datetime", "When the session was created (UTC)."),
    "started_at": ("datetime", "When it first started (UTC)."),
    "finished_at": ("datetime", "When it finished (UTC)."),
    "texts_version": (
        "integer",
        "Version of the study's texts the participant was shown when they consented or "
        "declined (texts_versions has them); empty for machine sessions.",
    ),
    "consented_at": (
        "datetime",
        "When the participant consented, recorded by the server; no advice is asked "
        "before it (UTC).",
    ),
    "declined_at": ("datetime", "When the participant last declined (UTC)."),
    "induction_done_at": (
        "datetime",
        "When the participant finished the three-step induction (pressed Start); advice "
        "is asked only after it (UTC).",
    ),
    "numerics_overrides": (
        "string",
        "Resumes that overrode the run's pinned numerics (JSON list: when, at which step, "
        "from what, to what, why); empty when the run was computed as pinned throughout.",
    ),
    "code_version": (
        "string",
        "Version of the code that computed the run (learner.provenance: a hash of sim/ and "
        "learner/), several joined by ' + ' when it was resumed by other code.",
    ),
    "provenance": (
        "string",
        "Where the run was computed (JSON list, one entry per start or resume: code version, "
        "commit, CPU kind, torch and Python versions, numerics, and the step it started from).",
    ),
    "replay_of": (
        "integer",
        "The session whose recorded advice this one replays (method replayed), when it is in "
        "the same database; empty otherwise. Deleting that session deletes its replays.",
    ),
    "advises": (
        "boolean",
        "True for an advisor: a session a batch trained as the agent-IDeepRL method's "
        "advisor (each attempt, passed its check or not, used or not), or whose checkpoint "
        "advises other sessions of the study: not one of the compared agents, and the report "
        "leaves it out.",
    ),
    "replay_source": (
        "string",
        "Where a replay's advice stream came from (JSON: study, session, export file); empty "
        "for sessions that are not replays.",
    ),
    "condition": (
        "string",
        "The online study's condition the participant was assigned to (assignments has how); "
        "empty outside an online study.",
    ),
    "outcome": (
        "string",
        "How the online visit ended: completed, declined, excluded (failed the check) or "
        "timed_out; empty while it goes on, and outside an online study.",
    ),
    "outcome_at": ("datetime", "When the visit's outcome was recorded (UTC)."),
    "actions": (
        "string",
        "The actions of the session's task in the learner's order (action i is the "
        "network's output i), by the names its steps' Q-value columns have (q_<name>), as a "
        "JSON list: a reader needs no task module to know them; action_0, action_1, ... "
        "where the exporting process could not load the task.",
    ),
    "run_spec": (
        "string",
        "The whole run as stored (learner.run.RunSpec's JSON document, with its version): "
        "what the API's `run` and `ideeprl batch` accept back, and what a replay reads.",
    ),
}
"""The session's own columns; the run's come from its declaration (`run_columns`)."""
KINDS = {bool: "boolean", int: "integer", float: "number", str: "string", dict: "string"}
TEXT_KEYS = ("title", "consent", "induction_1", "induction_2", "induction_3", "thanks")
TEXTS_COLUMNS: dict[str, tuple[str, str]] = {
    "study_id": ("integer", "Study the texts belong to."),
    "texts_version": (
        "integer",
        "Version number within the study, from 1; a new version is stored whenever the "
        "texts shown change (e.g. edited after sessions ran).",
    ),
    "content_hash": ("string", "SHA-256 of the version's texts (JSON, sorted keys)."),
    "created_at": ("datetime", "When this version was first shown (UTC)."),
    "title": ("string", "Page title, exactly as shown."),
    "consent": (
        "string",
        "Consent text, exactly as shown (placeholders filled in; plain text with ## "
        "headings, - bullets, **bold**).",
    ),
    "induction_1": ("string", "Induction step 1 (the scenario and expected results), as shown."),
    "induction_2": ("string", "Induction step 2 (the problem and how to solve it), as shown."),
    "induction_3": ("string", "Induction step 3 (how to use the interface), as shown."),
    "thanks": ("string", "Thank-you page text, as shown."),
}
ADVICE_COLUMNS: dict[str, tuple[str, str]] = {
    "session_id": ("integer", "Session the advice belongs to."),
    "advice_index": ("integer", "Index of the advice in its session, from 0."),
    "global_step": ("integer", "Global step the advice was for (from 1, pretraining included)."),
    "advisor": ("string", "Who advised: human, agent, oracle, random, fitted or replayed."),
    "action": (
        "integer",
        "Advised action, its index in the run's task's actions (the sorting robot's: 0 grab, "
        "1 move right, 2 move left, 3 drop); empty for a replay's "
        "request beyond its recorded stream (asked, counted against the budget, none given).",
    ),
    "action_name": ("string", "The advised action's words, as its task names it."),
    "greedy_action": (
        "integer",
        "The learner's own greedy choice for the same observation (if known).",
    ),
    "response_time_s": (
        "number",
        "Server side: time from the page first reading the request to the advice arriving; "
        "for people this includes the 3-D replay of the robot's last move (buttons still "
        "off) and network time; for machine advisors their compute time [s].",
    ),
    "decision_time_s": (
        "number",
        "Browser side (people only): time from the action buttons becoming active to the "
        "click or key, on the browser's monotonic clock (performance.now()): the "
        "participant's own decision time; for the fitted advisor and an oracle with "
        "simulated times the time it drew (never waited); empty for other machine "
        "advisors [s].",
    ),
    "requested_at": ("datetime", "Server side: when the page first read the request (UTC)."),
    "answered_at": ("datetime", "When the advice arrived (UTC)."),
    "observation_file": (
        "string",
        "PNG (lossless) of what the advisor saw: the learner's image; for a vector task the "
        "rendered frame, with the vector as JSON in its ideeprl-observation text.",
    ),
    "same_observation": (
        "boolean",
        "Replayed advice: whether the replay showed it the image its advisor saw (equal "
        "observation hashes); empty for advice given live and for requests beyond the stream.",
    ),
    "correct_action": (
        "integer",
        "The task's correct action at the advised step, its index as in action (the sorting "
        "rule's for the sorting robot, the shortest path's in the grid world): the advice is "
        "accurate when action equals it, or is one of correct_actions; empty where the task "
        "cannot say, and for advice stored before it was recorded.",
    ),
    "correct_actions": (
        "string",
        "Every action as right as correct_action at the advised step, it among them, their "
        'indices separated by spaces ("1 2": the grid world\'s moves that bring the agent '
        "equally near the goal): the advice is accurate when action is one of them; empty "
        "where the task cannot say, and for advice stored before it was recorded (its "
        "accuracy reads correct_action alone).",
    ),
}
FEEDBACK_COLUMNS: dict[str, tuple[str, str]] = {
    "session_id": ("integer", "Session the judgement belongs to (its run's feedback: evaluative)."),
    "feedback_index": ("integer", "Index of the judgement in its session, from 0."),
    "global_step": (
        "integer",
        "Global step whose action was judged (from 1, pretraining included); steps.csv has "
        "the step, its reward the environment's.",
    ),
    "evaluator": (
        "string",
        "Who judged: oracle or agent (machine evaluators), human (a participant), or replayed "
        "(a recorded session's ratings fed by order: ideeprl replay).",
    ),
    "action": (
        "integer",
        "The action judged: the learner's own, the one taken (0 grab, 1 move right, 2 move "
        "left, 3 drop for the sorting task).",
    ),
    "action_name": ("string", "The judged action's words, as its task names it."),
    "judgement": (
        "number",
        "The evaluator's judgement: 1 good (the action the oracle or the trained agent would "
        "take), -1 bad; empty: no answer.",
    ),
    "shaping": (
        "number",
        "What the judgement added to the environment's reward in the learner's memory: the "
        "run's feedback_weight times the judgement (0 without one) [reward].",
    ),
    "greedy_action": ("integer", "The learner's own greedy choice for the same observation."),
    "observation_hash": (
        "string",
        "The image the action was chosen on: its hash, as steps.csv's observation_hash.",
    ),
    "response_time_s": ("number", "The evaluator's compute time (machine evaluators) [s]."),
    "decision_time_s": (
        "number",
        "An oracle with simulated times: the time it drew (never waited); else empty [s].",
    ),
    "requested_at": ("datetime", "When the judgement was asked (UTC)."),
    "answered_at": ("datetime", "When it arrived (UTC)."),
    "correct_action": (
        "integer",
        "The task's correct action at the judged step, its index as in action (the sorting "
        "rule's for the sorting robot, the shortest path's in the grid world): a judgement "
        "is right when it is good and action equals it (or is one of correct_actions), or "
        "bad and action is none of them; empty where the task cannot say, and for judgements "
        "stored before it was recorded.",
    ),
    "correct_actions": (
        "string",
        "Every action as right as correct_action at the judged step, it among them, their "
        'indices separated by spaces ("1 2"); empty where the task cannot say, and for '
        "judgements stored before it was recorded (their rightness reads correct_action "
        "alone).",
    ),
}
ASSIGNMENT_COLUMNS: dict[str, tuple[str, str]] = {
    "session_id": ("integer", "The session the arrival got."),
    "condition": ("string", "The condition it was assigned to."),
    "block": (
        "integer",
        "Block of the block randomization, from 0: each block holds every condition once, in "
        "the order the seed gives.",
    ),
    "position": ("integer", "Position in the block, from 0."),
    "seed": ("integer", "The study's assignment seed (the same seed gives the same order)."),
    "refills_session_id": (
        "integer",
        "The session whose place this arrival refilled (a visit that ended early); empty for "
        "a place taken in sequence.",
    ),
    "assigned_at": ("datetime", "When the arrival was assigned (UTC)."),
}
PANEL_COLUMNS: dict[str, tuple[str, str]] = {
    "participant": ("string", "Pseudonym of the participant (as in sessions)."),
    "panel_id": (
        "string",
        "The participant's id at the panel (e.g. PROLIFIC_PID, workerId); pseudonymous (a "
        "keyed hash, the same person the same value) unless the export was asked for panel "
        "ids for payment (panel_ids=true).",
    ),
    "panel_params": (
        "string",
        "Every panel parameter of the arrival (JSON: study, submission, assignment ids); "
        "empty unless the export was asked for panel ids.",
    ),
    "created_at": ("datetime", "When the participant first arrived (UTC)."),
}
RECORD_EXTRA: dict[str, tuple[str, str]] = {
    "logged_at": ("datetime", "When the session's worker logged the record (UTC)."),
    "elapsed_s": ("number", "Seconds from the session's first start to the record [s]."),
}
STEP_ADVISED = ("boolean", "The step's action came from the advisor (advised_action is set).")
STAGE_DOCS = {
    "steps": "`pretrain` (pretraining stage: random actions, or advised ones: see "
    "`action_source` and `advised`) or `train` (training stage); the same vocabulary as "
    "episodes.csv. Advice is an action source, never a stage.",
    "episodes": "`pretrain` or `train`; the paper's curves and R_T use the `train` episodes.",
}
UNITS = {
    "reward": "reward",
    "collected_reward": "reward",
    "epsilon": "probability",
    "steps": "count",
    "placed_correct": "count",
    "misplaced": "count",
    "lost": "count",
    "advised_steps": "count",
    "advice_remaining": "count",
}


def _sql_type(column: Any) -> str:
    from sqlalchemy import Boolean, DateTime, Float, Integer

    kind = column.type
    for sql, name in ((Boolean, "boolean"), (Integer, "integer"), (Float, "number")):
        if isinstance(kind, sql):
            return name
    return "datetime" if isinstance(kind, DateTime) else "string"


def q_columns(tasks: Mapping[str, QActions]) -> list[Column]:
    """The steps' Q-value columns of these tasks (by name, in the order given): one per
    action name, shared by the tasks that have an action so named (each step fills its own
    task's, the others are empty: sessions.csv's `task` says which task a session ran)."""
    owners: dict[str, list[str]] = {}
    for task, actions in tasks.items():
        for index, (name, words) in enumerate(zip(actions.names, actions.words, strict=True)):
            owners.setdefault(name, []).append(f"action {index} of task {task} ({words})")
    columns = []
    for name, which in owners.items():
        empty = "" if len(which) == len(tasks) else "; empty for a step of a task without it"
        columns.append(
            column(
                f"q_{name}",
                "number",
                f"The learner's Q-value of {' or '.join(which)}, in the state the step's "
                f"action was chosen in{empty}.",
            )
        )
    return columns


def _record_columns(table: str, q: Mapping[str, QActions] | None = None) -> list[Column]:
    """Step or episode columns: types from the database model, descriptions from the
    docstrings under the learner's record fields; a step's Q-values as `q` names them."""
    from study.db.models import Episode, Step

    model, record = (Step, StepRecord) if table == "steps" else (Episode, EpisodeRecord)
    docs = field_docstrings(record)
    docs["stage"] = STAGE_DOCS[table]
    columns = [column("session_id", "integer", "Session the record belongs to.")]
    for c in model.__table__.columns:
        if c.name in ("id", "session_id", "wall_time"):
            continue
        if c.name in STORED_Q:
            if c.name == STORED_Q[0]:
                columns += q_columns(q or {"sorting": QActions.of(get_task("sorting"))})
            continue
        description = docs.get(c.name) or "(not documented)"
        columns.append(column(c.name, _sql_type(c), description, UNITS.get(c.name)))
    if table == "steps":
        columns.append(column("advised", *STEP_ADVISED))
    return columns + [column(name, *spec) for name, spec in RECORD_EXTRA.items()]


def run_columns() -> list[Column]:
    """One column per field of the run (the leaves of `learner.run.declared()`: `method`, `seed`,
    `config_batch_size`, `strategy_interval`, `reward_scheme`, ...), typed and documented
    by the declaration itself."""
    return [
        column(leaf.column, KINDS[leaf.kind], f"{leaf.doc} [{leaf.allowed()}]".replace("]]", "]"))
        for leaf in leaves(declared())
    ]


def table_columns(q: Mapping[str, QActions] | None = None) -> dict[str, list[Column]]:
    """Every exported table's typed, documented columns; the steps' Q-values those of the
    tasks `q` names (None: the sorting robot's, the default task's)."""
    own = [column(name, *spec) for name, spec in SESSION_COLUMNS.items()]
    sessions = own[:3] + run_columns() + own[3:]
    return {
        "sessions": sessions,
        "episodes": _record_columns("episodes"),
        "steps": _record_columns("steps", q),
        "advice": [column(name, *spec) for name, spec in ADVICE_COLUMNS.items()],
        "feedback": [column(name, *spec) for name, spec in FEEDBACK_COLUMNS.items()],
        "texts_versions": [column(name, *spec) for name, spec in TEXTS_COLUMNS.items()],
        "assignments": [column(name, *spec) for name, spec in ASSIGNMENT_COLUMNS.items()],
        "panel_ids": [column(name, *spec) for name, spec in PANEL_COLUMNS.items()],
        **{
            table: [column(name, *spec) for name, spec in specs.items()]
            for table, specs in VISIT_COLUMNS.items()
        },
    }
