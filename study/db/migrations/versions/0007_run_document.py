"""sessions.run: the run as one versioned JSON document, instead of twelve columns

Revision ID: 0007
Revises: 0006

Each session's method, seed, learner config, sorting rule, strategy and its options, advice
budget, advisor, oracle error rate, motion, scenario, episodes and episode limit become one
document (`learner.run.RunSpec.to_json()`, version 1), and the columns go. The advice budget,
episodes and episode limit were kept twice (a column and the config): the config's value
wins where they differ (the column was derived from it). Stable-Baselines3's `sb3_*`
settings, stored in the config, are left out: they are derived from the config.

Rows stored before this revision never recorded their preset; it is read back as the preset
their config is (`authors` for the Keras-style fit with a softmax head, `modern` for a
target network with Double DQN and the Huber loss, else `paper`): the config itself is kept
whole, so this name changes nothing a run does. Their numerics (`precision`, `torch_threads`
and `device` of `auto`/0) were never pinned: they stay as stored, and are pinned on this
machine when the session next starts.

The transformation is written out here, not imported, so that the migration keeps meaning
what it meant when later code changes.
"""

from collections.abc import Sequence
from typing import Any

import sqlalchemy as sa
from alembic import op

revision: str = "0007"
down_revision: str | None = "0006"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

OLD_COLUMNS = (
    "method",
    "seed",
    "config",
    "sort_rule",
    "strategy",
    "strategy_options",
    "advice_budget",
    "advisor_checkpoint",
    "oracle_error_rate",
    "motion",
    "scenario",
    "episodes",
    "max_episode_steps",
)
UNADVISED = ("autonomous", "sb3-dqn")
STRATEGY_DEFAULTS: dict[str, dict[str, float]] = {
    "early": {},
    "alternating": {"interval": 2},
    "importance": {"threshold": 0.1},
    "mistake_correcting": {"threshold": 0.1},
}
"""The strategies' options as of this revision (NULL options read as these)."""


def _preset(config: dict[str, Any]) -> str:
    if config.get("fit") == "keras" and config.get("head") == "softmax":
        return "authors"
    if config.get("target_network") and config.get("double_dqn") and config.get("loss") == "huber":
        return "modern"
    return "paper"


def run_document(row: dict[str, Any]) -> dict[str, Any]:
    """The version-1 run document of a session row stored before this revision."""
    method = row["method"]
    advised = method not in UNADVISED
    config = {k: v for k, v in (row["config"] or {}).items() if not k.startswith("sb3_")}
    config.setdefault("episodes", row["episodes"])
    config.setdefault("max_episode_steps", row["max_episode_steps"])
    if advised:
        config.setdefault("advice_budget", row["advice_budget"])
    else:
        config["advice_budget"] = 0
    strategy = (row["strategy"] or "early") if advised else "early"
    options: dict[str, Any] = {"interval": None, "threshold": None}
    if advised:
        options.update(STRATEGY_DEFAULTS.get(strategy, {}))
        options.update(row["strategy_options"] or {})
    return {
        "version": 1,
        "method": method,
        "seed": row["seed"],
        "preset": _preset(config),
        "config": config,
        "strategy": strategy,
        "strategy_options": options,
        "advisor_checkpoint": row["advisor_checkpoint"],
        "error_rate": (row["oracle_error_rate"] or 0.0) if method == "oracle" else 0.0,
        "motion": row["motion"],
        "sort_rule": row["sort_rule"],
        "scenario": {
            "reward_scheme": "paper",
            "grasp_failure_rate": 0.0,
            "knock_off_rate": 0.0,
            **(row["scenario"] or {}),
        },
    }


def _sessions(columns: Sequence[str]) -> sa.TableClause:
    json_columns = {"config", "sort_rule", "strategy_options", "scenario", "run"}
    return sa.table(
        "sessions",
        sa.column("id", sa.Integer),
        *(sa.column(c, sa.JSON if c in json_columns else sa.String) for c in columns),
    )


def upgrade() -> None:
    with op.batch_alter_table("sessions", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.add_column(sa.Column("run", sa.JSON(), nullable=True))
        batch.add_column(sa.Column("numerics_overrides", sa.JSON(), nullable=True))
    bind = op.get_bind()
    old = _sessions(OLD_COLUMNS)
    new = _sessions(("run",))
    rows = [dict(r._mapping) for r in bind.execute(sa.select(old))]
    for row in rows:
        for name in ("seed", "advice_budget", "episodes", "max_episode_steps"):
            row[name] = None if row[name] is None else int(row[name])
        if row["oracle_error_rate"] is not None:
            row["oracle_error_rate"] = float(row["oracle_error_rate"])
        bind.execute(sa.update(new).where(new.c.id == row["id"]).values(run=run_document(row)))
    bind.execute(sa.text("UPDATE sessions SET numerics_overrides = '[]'"))
    with op.batch_alter_table("sessions", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.alter_column("run", existing_type=sa.JSON(), nullable=False)
        batch.alter_column("numerics_overrides", existing_type=sa.JSON(), nullable=False)
        for column in OLD_COLUMNS:
            batch.drop_column(column)


def downgrade() -> None:
    with op.batch_alter_table("sessions", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.add_column(sa.Column("method", sa.String(20), nullable=True))
        batch.add_column(sa.Column("seed", sa.Integer(), nullable=True))
        batch.add_column(sa.Column("config", sa.JSON(), nullable=True))
        batch.add_column(sa.Column("sort_rule", sa.JSON(), nullable=True))
        batch.add_column(sa.Column("strategy", sa.String(40), nullable=True))
        batch.add_column(sa.Column("strategy_options", sa.JSON(), nullable=True))
        batch.add_column(sa.Column("advice_budget", sa.Integer(), nullable=True))
        batch.add_column(sa.Column("advisor_checkpoint", sa.Text(), nullable=True))
        batch.add_column(sa.Column("oracle_error_rate", sa.Float(), nullable=True))
        batch.add_column(sa.Column("motion", sa.String(20), nullable=True))
        batch.add_column(sa.Column("scenario", sa.JSON(), nullable=True))
        batch.add_column(sa.Column("episodes", sa.Integer(), nullable=True))
        batch.add_column(sa.Column("max_episode_steps", sa.Integer(), nullable=True))
    bind = op.get_bind()
    table = sa.table(
        "sessions",
        sa.column("id", sa.Integer),
        sa.column("run", sa.JSON),
        *(sa.column(c) for c in OLD_COLUMNS),
    )
    for row in bind.execute(sa.select(table.c.id, table.c.run)).all():
        run = row.run
        advised = run["method"] not in UNADVISED
        bind.execute(
            sa.update(table)
            .where(table.c.id == row.id)
            .values(
                method=run["method"],
                seed=run["seed"],
                config=run["config"],
                sort_rule=run["sort_rule"],
                strategy=run["strategy"] if advised else None,
                strategy_options={k: v for k, v in run["strategy_options"].items() if v is not None}
                if advised
                else None,
                advice_budget=run["config"]["advice_budget"] if advised else 0,
                advisor_checkpoint=run["advisor_checkpoint"],
                oracle_error_rate=run["error_rate"] if run["method"] == "oracle" else None,
                motion=run["motion"] or ("physics" if run["method"] == "human" else "fast"),
                scenario=run["scenario"],
                episodes=run["config"]["episodes"],
                max_episode_steps=run["config"]["max_episode_steps"],
            )
        )
    with op.batch_alter_table("sessions", table_kwargs={"sqlite_autoincrement": True}) as batch:
        for name, kind in (
            ("method", sa.String(20)),
            ("seed", sa.Integer()),
            ("config", sa.JSON()),
            ("sort_rule", sa.JSON()),
            ("motion", sa.String(20)),
            ("episodes", sa.Integer()),
        ):
            batch.alter_column(name, existing_type=kind, nullable=False)
        batch.drop_column("numerics_overrides")
        batch.drop_column("run")
