"""Baselines in batch: N agents per method, in parallel processes or on Ray, as sessions of
a study in the platform's database (so exports and the report treat them like human ones).

    from runs.batch import BatchSpec, RunnerOptions, run_batch
    result = run_batch(BatchSpec(methods=("autonomous", "agent"), agents=10), study_id, url)

`ideeprl batch` is the command line; `study.services.episodes.load_episodes` gives the
analysis package its episode table.
"""

from runs.batch.runner import BatchResult, RunnerOptions, RunState, describe, run_batch
from runs.batch.spec import BATCH_METHODS, BatchError, BatchSpec, Run, plan_runs
from study.services.episodes import EPISODE_TABLE_COLUMNS, load_episodes

__all__ = [
    "BATCH_METHODS",
    "EPISODE_TABLE_COLUMNS",
    "BatchError",
    "BatchResult",
    "BatchSpec",
    "Run",
    "RunState",
    "RunnerOptions",
    "describe",
    "load_episodes",
    "plan_runs",
    "run_batch",
]
