"""The settings table of the comparability audit (`analysis.audit`), from runs.

One row per session: its method, its learner (the preset and the config fields that differ
from it), one column per other setting of the run's declaration (`learner.run.RunSpec`'s
leaves of role `setting`), and the treatment (`advice`). Made the same way from the
database (`study.services.episodes.session_settings`) and from an export
(`analysis.exported`), so a field added to the run is audited by itself.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import Any

import pandas as pd

from analysis.audit import describe_learner
from analysis.episodes import arm_of
from learner import sb3_spec
from learner.config import PRESETS, DQNConfig
from learner.fields import leaves
from learner.run import RunSpec, declared

PROVENANCE = {
    "code_version": "code",
    "cpu_kind": "cpu",
    "torch_version": "torch",
    "conv_kernel": "conv_kernel",
}
"""The provenance the audit compares (`learner.provenance.record`): its column, and the
record's key (the first layer's kernel under its `numerics`). Arms computed by other code,
on another CPU kind or torch, or by another first-layer kernel are flagged."""


def settings_table(
    runs: Sequence[tuple[int, RunSpec]],
    provenance: Mapping[int, Sequence[Mapping[str, Any]]] | None = None,
) -> pd.DataFrame:
    """The audit's table for `(session_id, run)` pairs; with `provenance` (each session's
    records of where it was computed) also the code version, CPU kind, torch version and
    first-layer kernel (several joined by ' + ' when a run was resumed elsewhere)."""
    presets = {name: DQNConfig.preset(name).to_dict() for name in PRESETS}
    settings = [
        leaf
        for leaf in leaves(declared())
        if leaf.role == "setting" and leaf.path[0] != "config" and leaf.name != "preset"
    ]
    rows = []
    for session_id, run in runs:
        spec = run.normalized()
        config = spec.config.to_dict()
        learner = (
            sb3_spec.describe(spec.sb3, config)  # another learner altogether: the audit flags it
            if spec.learner == "sb3-dqn"
            else describe_learner(config, presets)
        )
        values = spec.values()
        rows.append(
            {
                "session_id": session_id,
                "method": arm_of(spec),
                "learner": learner,
                **{leaf.name: _text(values[leaf.name]) for leaf in settings},
                **(
                    {}
                    if provenance is None
                    else {
                        column: where(provenance.get(session_id, ()), key)
                        for column, key in PROVENANCE.items()
                    }
                ),
                "advice": "none"
                if not spec.advised
                else (
                    f"evaluative feedback ({spec.feedback_method}, "
                    f"weight {spec.feedback_weight:g}), "
                    if spec.feedback == "evaluative"
                    else ""
                )
                + f"{spec.strategy}{_options(spec.strategy_options.given())}, "
                f"budget {spec.advice_budget}",
            }
        )
    return pd.DataFrame(rows)


def where(records: Sequence[Mapping[str, Any]], key: str) -> str:
    """One provenance value of a run: its records' distinct values, in order, joined by
    ' + ' ('not recorded' for a run stored before provenance was)."""
    seen = list(dict.fromkeys(str(_recorded(r, key)) for r in records))
    return " + ".join(seen) if seen else "not recorded"


def _recorded(record: Mapping[str, Any], key: str) -> Any:
    """A record's value under `key`, or under its `numerics` (a numerics key a record made
    before that key was: 'not recorded')."""
    if key in record:
        return record[key]
    return record.get("numerics", {}).get(key, "not recorded")


def _text(value: Any) -> Any:
    """A setting as the audit compares it (a map as sorted JSON)."""
    return json.dumps(value, sort_keys=True) if isinstance(value, dict | list) else value


def _options(options: dict[str, Any] | None) -> str:
    """A strategy's options in words, e.g. " (interval 3)"; "" when it has none."""
    given = ", ".join(f"{k} {v}" for k, v in sorted((options or {}).items()))
    return f" ({given})" if given else ""
