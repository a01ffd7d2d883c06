"""R_T rescored from the step logs under each of the task's reward schemes.

The same behaviour scores differently under different accountings: what a method
"collects" depends on the rule as much as on the learner. Rescoring each logged training
step under every reward scheme its task declares (`tasks.RewardSchemes`: for the sorting
robot a placement keeps its reward, every other step costs what the scheme says, see
`sim.rewards.rescore`) shows each method's R_T under every scheme, so methods run under
different schemes can still be compared under one. A study that ran several tasks is
rescored task by task: a task's schemes score only its own runs, so each session is
rescored under its own task's schemes and compared with its own task's baseline. A task
that declares no schemes, or a scheme whose count is not in the record, is not rescored:
`tasks.RescoreError` says why."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import pandas as pd

from analysis.episodes import method_name, order_methods
from analysis.stats import improvement_pct, student_t_test
from tasks import RecordedEpisode, RescoreError, Task, TaskOptions, get_task

STEP_COLUMNS: tuple[str, ...] = (
    "session_id",
    "episode",
    "episode_step",
    "reward",
    "terminated",
)
"""One row per training step (episode 1..N within the session, `episode_step` from 1, every
step of each episode present: a step's cost depends on its number in the episode), and an
optional `outcome` (`tasks.Task.outcomes` or none; missing in logs recorded before it was
kept): an episode whose steps all have one is rescored by them, else by its rewards."""


@dataclass(frozen=True)
class Plan:
    """How one task's sessions are rescored: the task, and per session the scheme it was
    scored under and its task options."""

    task: Task
    schemes: dict[int, str]
    options: Mapping[int, TaskOptions]


@dataclass(frozen=True)
class Plans:
    """The rescoring of a study's sessions task by task: a task's reward schemes score
    only its own runs, so each task's sessions are rescored under that task's schemes."""

    tasks: tuple[Plan, ...]
    """The tasks whose sessions are rescored, by name."""
    not_rescored: Mapping[str, str]
    """Each task whose sessions are not rescored, by name, and why."""

    @property
    def schemes(self) -> tuple[str, ...]:
        """Every rescored task's schemes, task by task, each once."""
        names = [p.task.reward_schemes.names for p in self.tasks if p.task.reward_schemes]
        return tuple(dict.fromkeys(n for each in names for n in each))


def plan(settings: pd.DataFrame) -> Plans:
    """The rescoring of the sessions of a settings table (`analysis.settings`: `task`,
    `task_options` and a task's own options as columns; a table without `task` ran the
    sorting robot), task by task. A task that declares no schemes, or whose settings do not
    say a session's scheme, is not rescored (`Plans.not_rescored` says why);
    `RescoreError` says why when no task's sessions can be rescored."""
    names = sorted(set(settings["task"])) if "task" in settings else ["sorting"]
    planned, skipped = [], {}
    for name in names:
        rows = settings[settings["task"] == name] if "task" in settings else settings
        try:
            planned.append(_task_plan(get_task(name), rows))
        except RescoreError as error:
            skipped[name] = str(error)
    if not planned:
        raise RescoreError("; ".join(skipped.values()))
    return Plans(tuple(planned), skipped)


def _task_plan(task: Task, settings: pd.DataFrame) -> Plan:
    """The rescoring of one task's sessions; `RescoreError` says why they cannot be."""
    declared = task.reward_schemes
    if declared is None:
        raise RescoreError(
            f"task {task.name} declares no reward schemes: its runs' rewards are reported "
            "as logged, not rescored"
        )
    schemes, options = {}, {}
    for row in settings.to_dict("records"):
        given = _task_options(row.get("task_options"))
        own = {k: row[k] for k in task.options if k in row and k not in given}
        session = int(row["session_id"])
        options[session] = {**own, **given}
        if declared.option and declared.option not in options[session]:
            raise RescoreError(
                f"the settings do not say which reward scheme (`{declared.option}`) session "
                f"{session} of task {task.name} was scored under"
            )
        schemes[session] = declared.logged(options[session])
    return Plan(task, schemes, options)


def rescored_by_task(
    steps: pd.DataFrame, plans: Plans, n_episodes: int | None = None
) -> pd.DataFrame:
    """`rescored_totals` of each task's sessions under every rescored task's schemes
    (`Plans.schemes`), one table: a scheme a session's task does not declare leaves its
    R_T empty, the scheme named in `undeclared`. Sessions of tasks not rescored are left
    out."""
    tables = [
        rescored_totals(
            steps[steps["session_id"].isin(list(p.schemes))], p.schemes, n_episodes, p.task,
            p.options, plans.schemes,
        )
        for p in plans.tasks
    ]  # fmt: skip
    return pd.concat(tables, ignore_index=True)


def _task_options(value: object) -> dict[str, object]:
    """A settings row's task options (JSON text in a settings table, or a map)."""
    if isinstance(value, str) and value:
        value = json.loads(value)
    return dict(value) if isinstance(value, Mapping) else {}


def rescored_totals(
    steps: pd.DataFrame,
    schemes: dict[int, str],
    n_episodes: int | None = None,
    task: Task | str = "sorting",
    options: Mapping[int, TaskOptions] | None = None,
    targets: Sequence[str] | None = None,
) -> pd.DataFrame:
    """Per session of one task: R_T as logged and under each of `targets` (`R_T_<scheme>`
    columns; the task's schemes when None), over its first `n_episodes` episodes (all when
    None). `schemes` maps a session to the scheme its steps were scored under, `options`
    to its task options (the task's defaults when absent). A scheme the task declares but
    cannot rescore a session's steps under leaves its R_T empty (NaN), the reason in
    `not_rescored`; a target the task does not declare leaves it empty too, named in
    `undeclared`. `RescoreError` when the task declares no schemes."""
    task = get_task(task) if isinstance(task, str) else task
    declared = task.reward_schemes
    if declared is None:
        raise RescoreError(
            f"task {task.name} declares no reward schemes: its runs' rewards are reported "
            "as logged, not rescored"
        )
    wanted = tuple(targets) if targets is not None else declared.names
    table = steps
    if n_episodes is not None:
        table = table[table["episode"] <= n_episodes]
    table = table.sort_values(["session_id", "episode", "episode_step"])
    rows = []
    for session_id, group in table.groupby("session_id", sort=True):
        scheme = schemes[int(session_id)]
        given = (options or {}).get(int(session_id), {})
        row: dict[str, object] = {
            "session_id": int(session_id),
            "task": task.name,
            "scheme": scheme,
            "R_T_logged": float(group["reward"].sum()),
        }
        episodes = [
            RecordedEpisode(
                tuple(float(r) for r in e["reward"]),
                tuple(bool(t) for t in e["terminated"]),
                _outcomes(e),
            )
            for _, e in group.groupby("episode", sort=True)
        ]
        row["by_outcomes"] = all(e.outcomes is not None for e in episodes)
        reasons = []
        for target in wanted:
            row[f"R_T_{target}"] = float("nan")
            if target not in declared.names:
                continue
            try:
                row[f"R_T_{target}"] = sum(
                    sum(task.rescore(e, scheme, target, given)) for e in episodes
                )
            except RescoreError as error:
                reasons.append(f"{target}: {error}")
        row["not_rescored"] = "; ".join(dict.fromkeys(reasons))
        row["undeclared"] = ", ".join(t for t in wanted if t not in declared.names)
        rows.append(row)
    return pd.DataFrame(rows)


def rescored_schemes(table: pd.DataFrame) -> list[str]:
    """The schemes a rescoring table (or its totals) has an `R_T_<scheme>` column for."""
    return [
        c.removeprefix("R_T_") for c in table.columns if c.startswith("R_T_") and c != "R_T_logged"
    ]


def _outcomes(episode: pd.DataFrame) -> tuple[str, ...] | None:
    """The episode's step outcomes, or None when any is unknown (an older log)."""
    if "outcome" not in episode:
        return None
    values = list(episode["outcome"])
    if any(v is None or (isinstance(v, float) and v != v) for v in values):
        return None
    return tuple(str(v) for v in values)


def rescoring_table(
    totals: pd.DataFrame, methods: dict[int, str], baseline: str | None = None
) -> pd.DataFrame:
    """Per method (per task and method where the totals name their tasks, each task's
    methods against that task's baseline, under that task's schemes): the schemes its
    sessions were scored under, mean R_T as logged and under each scheme, and (with a
    baseline) the improvement in percent under each scheme and, under each scheme, Welch's
    p for the agents' R_T against the baseline's (NaN with fewer than two agents on a
    side)."""
    if "task" not in totals:
        return _method_table(totals, methods, baseline, rescored_schemes(totals))
    tables = []
    for name, group in totals.groupby("task", sort=True):
        declared = get_task(str(name)).reward_schemes
        own = declared.names if declared is not None else ()
        schemes = [s for s in rescored_schemes(totals) if s in own]
        table = _method_table(group, methods, baseline, schemes)
        tables.append(table.assign(task=name)[["task", *table.columns]])
    return pd.concat(tables, ignore_index=True)


def _method_table(
    totals: pd.DataFrame, methods: dict[int, str], baseline: str | None, schemes: list[str]
) -> pd.DataFrame:
    """`rescoring_table` of sessions of one task, under `schemes`."""
    frame = totals.assign(method=totals["session_id"].map(methods))
    out = []
    for method in order_methods(frame["method"], baseline):
        group = frame[frame["method"] == method]
        row: dict[str, object] = {
            "method": method,
            "name": method_name(method),
            "agents": len(group),
            "logged_under": " | ".join(sorted(set(group["scheme"]))),
            "R_T_logged": group["R_T_logged"].mean(),
        }
        for scheme in schemes:
            row[f"R_T_{scheme}"] = group[f"R_T_{scheme}"].mean()
        out.append(row)
    table = pd.DataFrame(out)
    if baseline is not None and baseline in set(table["method"]):
        base = table.set_index("method")
        for logged_or_scheme in ("logged", *schemes):
            column = f"R_T_{logged_or_scheme}"
            reference = float(base.loc[baseline, column])
            table[f"improvement_{logged_or_scheme}"] = [
                improvement_pct(value, reference) for value in table[column]
            ]
        # Under one scheme the agents' R_T are comparable, so they can be tested.
        ours = frame["method"] == baseline
        for scheme in schemes:
            column = f"R_T_{scheme}"
            table[f"p_welch_{scheme}"] = [
                float("nan")
                if method == baseline
                else student_t_test(
                    frame.loc[frame["method"] == method, column].to_numpy(),
                    frame.loc[ours, column].to_numpy(),
                    equal_var=False,
                )[1]
                for method in table["method"]
            ]
    return table
