"""Each method against the baseline the way a reviewer expects: one primary test, the
others as secondary, and effect sizes that do not need a test.

The runs are the independent units, so the primary test compares the agents' R_T: Welch's
two-sample t-test (unequal variances), or, when every agent of the method has a baseline
agent of the same seed (`primary="paired"`, as a plan may fix for arms that share seeds),
the paired t-test. Secondary, reported beside it and labelled so: Welch, a permutation
test of the difference in means (exact when the arms are small, else 10,000 seeded
resamples), Mann-Whitney's U, the paired t-test where seeds pair, and the probability of
improvement (Agarwal et al. 2021, `rliable`: the chance that a random agent of the method
beats a random agent of the baseline, ties counting half) with a percentile bootstrap
interval. The paper's own test (its Table 2, average curves, episodes as samples) stays in
the report under its own heading; it is not among these.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from analysis.episodes import order_methods, validate_episodes
from analysis.intervals import CONFIDENCE, RESAMPLES, SEED

PRIMARY = ("welch", "paired")
"""The primary test of a comparison: Welch's test of the agents' R_T, or the paired t-test
over seeds both arms ran."""
COLUMNS = [
    "method", "baseline", "n", "n_baseline", "n_paired", "difference", "primary",
    "primary_statistic", "primary_p", "welch_t", "welch_p", "permutation_p",
    "mann_whitney_u", "mann_whitney_p", "paired_t", "paired_p",
    "probability_of_improvement", "poi_low", "poi_high",
]  # fmt: skip


def probability_of_improvement(a: np.ndarray, b: np.ndarray) -> float:
    """P(X > Y) + P(X = Y) / 2 for X an agent of `a`, Y one of `b` (all pairs)."""
    greater = (a[:, None] > b[None, :]).mean()
    equal = (a[:, None] == b[None, :]).mean()
    return float(greater + equal / 2)


def _poi_interval(a: np.ndarray, b: np.ndarray, rng: np.random.Generator) -> tuple[float, float]:
    """Percentile bootstrap interval of the probability of improvement, agents of each arm
    resampled independently (as `rliable` does)."""
    draws = np.empty(2000)
    for i in range(len(draws)):
        draws[i] = probability_of_improvement(
            rng.choice(a, size=len(a)), rng.choice(b, size=len(b))
        )
    tail = (1 - CONFIDENCE) / 2 * 100
    low, high = np.percentile(draws, [tail, 100 - tail])
    return float(low), float(high)


def _permutation_p(a: np.ndarray, b: np.ndarray) -> float:
    result = stats.permutation_test(
        (a, b),
        lambda x, y, axis: np.mean(x, axis=axis) - np.mean(y, axis=axis),
        permutation_type="independent",
        vectorized=True,
        n_resamples=RESAMPLES,
        alternative="two-sided",
        random_state=SEED,
    )
    return float(result.pvalue)


CONTROL = "procedure"
"""The procedure control's method: each advised method is also compared with it, the one
comparison that tells the advice apart from the advising procedure."""
ADVISED = ("agent", "human", "oracle", "random")


def comparison_pairs(methods: list[str], baseline: str | None) -> list[tuple[str, str]]:
    """(method, against) pairs: every method against the baseline, and every advised method
    against the procedure control when there is one (a judged arm, `oracle-evaluative`,
    against the control of its kind, `procedure-evaluative`)."""
    pairs = [(m, baseline) for m in methods if baseline is not None and m != baseline]
    for method in methods:
        advisor, dash, kind = method.partition("-")
        control = CONTROL + dash + kind
        if advisor in ADVISED and control in methods and (method, control) not in pairs:
            pairs.append((method, control))
    return pairs


def compare(episodes: pd.DataFrame, baseline: str | None, primary: str = "welch") -> pd.DataFrame:
    """One row per comparison (`comparison_pairs`, `COLUMNS`). `primary` is `welch` or
    `paired` (falls back to Welch, said in the row, when the seeds do not pair)."""
    if primary not in PRIMARY:
        raise ValueError(f"primary must be one of {', '.join(PRIMARY)}")
    table = validate_episodes(episodes)
    if baseline is not None and baseline not in set(table["method"]):
        baseline = None
    if "seed" not in table:  # seeds unknown: no agent pairs with another
        table = table.assign(seed=-1 - table["session_id"])
    totals = table.groupby(["method", "seed", "session_id"])["collected_reward"].sum()
    totals = totals.reset_index()
    rng = np.random.default_rng(SEED)
    rows = [
        _compare(totals, method, against, primary, rng)
        for method, against in comparison_pairs(order_methods(table["method"], baseline), baseline)
    ]
    return pd.DataFrame(rows, columns=COLUMNS)


def _compare(
    totals: pd.DataFrame, method: str, baseline: str, primary: str, rng: np.random.Generator
) -> dict[str, object]:
    base = totals[totals["method"] == baseline]
    arm = totals[totals["method"] == method]
    a, b = arm["collected_reward"].to_numpy(), base["collected_reward"].to_numpy()
    row: dict[str, object] = dict.fromkeys(COLUMNS, np.nan)
    row.update(method=method, baseline=baseline, n=len(a), n_baseline=len(b))
    row["difference"] = float(a.mean() - b.mean()) if len(a) and len(b) else np.nan
    varied = len(a) >= 2 and len(b) >= 2 and np.ptp(np.concatenate([a, b])) > 0
    if varied:
        welch = stats.ttest_ind(a, b, equal_var=False)
        row["welch_t"], row["welch_p"] = float(welch.statistic), float(welch.pvalue)
        row["permutation_p"] = _permutation_p(a, b)
        mw = stats.mannwhitneyu(a, b, alternative="two-sided")
        row["mann_whitney_u"], row["mann_whitney_p"] = float(mw.statistic), float(mw.pvalue)
    if len(a) and len(b):
        row["probability_of_improvement"] = probability_of_improvement(a, b)
        row["poi_low"], row["poi_high"] = _poi_interval(a, b, rng)
    paired = arm.merge(base, on="seed", suffixes=("", "_base"))
    seeds_pair = len(paired) == len(a) == len(b) and len(paired) >= 2
    row["n_paired"] = len(paired)
    differences = paired["collected_reward"] - paired["collected_reward_base"]
    if len(paired) >= 2 and np.ptp(differences.to_numpy()) > 0:
        test = stats.ttest_rel(paired["collected_reward"], paired["collected_reward_base"])
        row["paired_t"], row["paired_p"] = float(test.statistic), float(test.pvalue)
    chosen = "paired" if primary == "paired" and seeds_pair else "welch"
    row["primary"] = chosen if primary == chosen else "welch (seeds do not pair)"
    row["primary_statistic"], row["primary_p"] = row[f"{chosen}_t"], row[f"{chosen}_p"]
    return row
