"""The comparability audit: are the compared methods' numbers made under the same rules?

The paper's headline compares an autonomous learner scored under one reward accounting with
advised learners scored under another (shared/reference/README.md). A study platform must
not repeat that silently: every report lists, per method, the settings its sessions ran
under, says at the top when compared methods differ in any setting that is not the
treatment itself (who advises, how, how much), and withholds the t-tests of such pairs
unless the caller asks for them (`allow_mismatch`), with the warning kept.

Pure pandas over a settings table, one row per session (`FIXED_COLUMNS` and a column per
setting, which the server derives from the run's declaration, so a field added to the run
is audited by itself); nothing here reads the database.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass
from itertools import combinations
from typing import Any

import pandas as pd

from analysis.episodes import method_name, order_methods
from learner.config import DQNConfig
from learner.fields import leaves

FIXED_COLUMNS: tuple[str, ...] = ("session_id", "method", "learner", "advice")
"""Columns every settings table has: `learner` (the preset and the config fields that differ
from it, as text) and `advice` (strategy and budget: the treatment). Every other column is
a setting compared methods must share, one per field of the run the server declares
(`learner.run.RunSpec` leaves of role `setting` outside the learner config)."""

LABELS: dict[str, str] = {
    "learner": "learner preset and options",
    "reward_scheme": "reward scheme",
    "motion": "motion mode",
    "sort_rule": "sorting rule",
    "cpu_kind": "CPU kind",
    "conv_kernel": "first-layer kernel",
}
"""A setting's name in words, where it is not its column's with spaces."""

RUNTIME_FIELDS = tuple(leaf.name for leaf in leaves(DQNConfig) if leaf.role != "setting")
"""Learner config fields that do not change what is learned (where it runs, how fast the
same function is computed), or are the treatment or the report's own cut: their declared
roles (`learner.fields.ROLES`) are numerics, treatment and scale, not setting."""


def label(column: str) -> str:
    """A setting's column in words."""
    return LABELS.get(column, column.replace("_", " "))


def compared(settings: pd.DataFrame) -> dict[str, str]:
    """The settings table's compared columns and their labels, `learner` first."""
    return {
        c: label(c)
        for c in ("learner", *settings.columns)
        if c not in FIXED_COLUMNS or c == "learner"
    }


def describe_learner(config: dict[str, Any], presets: dict[str, dict[str, Any]]) -> str:
    """The preset a config is, plus the fields where it differs from it: the closest preset
    by number of differing fields (e.g. `authors`, `paper + gamma=0.99`)."""

    def differences(base: dict[str, Any]) -> dict[str, Any]:
        return {k: v for k, v in config.items() if k not in RUNTIME_FIELDS and base.get(k) != v}

    name, diff = min(
        ((name, differences(base)) for name, base in presets.items()),
        key=lambda item: len(item[1]),
    )
    extra = ", ".join(f"{k}={json.dumps(v)}" for k, v in sorted(diff.items()))
    return f"{name} + {extra}" if extra else name


@dataclass(frozen=True)
class Audit:
    """What each method ran under, and which compared pairs differ."""

    methods: pd.DataFrame
    """Per method: its sessions and each setting (several values joined by ' | ')."""
    mismatches: dict[tuple[str, str], list[str]]
    """Pairs of methods (in display order) and the settings, in words, in which they differ."""
    mixed: dict[str, list[str]]
    """Methods whose own sessions differ, and in which settings."""

    @property
    def comparable(self) -> bool:
        return not self.mismatches and not self.mixed

    def differ(self, a: str, b: str) -> list[str]:
        """The settings in which methods a and b differ (either order)."""
        return self.mismatches.get((a, b)) or self.mismatches.get((b, a)) or []

    def warnings(self) -> list[str]:
        """Sentences for the top of a report; empty when everything compares."""
        out = []
        for (a, b), what in self.mismatches.items():
            out.append(
                f"{method_name(a)} and {method_name(b)} were run under different settings "
                f"({', '.join(what)}): their numbers are not comparable as they stand"
                + (
                    " (the rescoring table scores the same behaviour under one scheme)."
                    if label("reward_scheme") in what
                    else "."
                )
            )
        for method, what in self.mixed.items():
            out.append(
                f"The {method_name(method)} sessions differ among themselves "
                f"({', '.join(what)}): its mean mixes them."
            )
        return out

    def power_cautions(self, methods: Iterable[str], baseline: str) -> list[str]:
        """A caution for each method whose baseline ran under other settings: a power
        analysis plans for the observed effect, which then is not the treatment's alone."""
        return [
            f"Caution: {method_name(m)}'s baseline {method_name(baseline)} ran under other "
            f"settings ({', '.join(what)}): the effect planned for mixes the treatment with "
            "that difference, so the agents needed are for a comparison that is not "
            f"comparable as it stands; plan from a baseline run under {method_name(m)}'s "
            "settings."
            for m in methods
            if m != baseline and (what := self.differ(m, baseline))
        ]


def audit(settings: pd.DataFrame, baseline: str | None = None) -> Audit:
    """The audit of the sessions in `settings` (`FIXED_COLUMNS` and one column per compared
    setting)."""
    missing = [c for c in FIXED_COLUMNS if c not in settings]
    assert not missing, f"settings table lacks {missing}"
    columns = compared(settings)
    order = order_methods(settings["method"], baseline)
    values: dict[str, dict[str, list[str]]] = {}
    rows = []
    for method in order:
        group = settings[settings["method"] == method]
        values[method] = {c: sorted(set(map(str, group[c]))) for c in (*columns, "advice")}
        rows.append(
            {
                "method": method,
                "name": method_name(method),
                "sessions": len(group),
                **{c: " | ".join(v) for c, v in values[method].items()},
            }
        )
    mixed = {m: [text for c, text in columns.items() if len(values[m][c]) > 1] for m in order}
    mismatches = {}
    for a, b in combinations(order, 2):
        differ = [text for c, text in columns.items() if values[a][c] != values[b][c]]
        if differ:
            mismatches[(a, b)] = differ
    return Audit(
        methods=pd.DataFrame(rows),
        mismatches=mismatches,
        mixed={m: what for m, what in mixed.items() if what},
    )
