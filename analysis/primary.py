"""The pre-registered primary test (`analysis.preregistration`), with which a report
leads: the design's measure and test between its two conditions at the design's alpha,
uncorrected (it is the one test fixed before the data), and the power the study had for
its observed spread (`analysis.power.normal_power`, the normal approximation: for the
design's smallest effect worth detecting where it gives one, and the difference it could
detect with 80 % power). Every other test of the report is exploratory."""

from __future__ import annotations

import math

import pandas as pd
from scipy import stats

from analysis.between import Tested, fisher, mann_whitney, welch
from analysis.human import Visits, check_rates, flow, participants
from analysis.power import normal_power
from analysis.preregistration import MEASURES, RATE, TEST_NAMES, Preregistered

TARGET = 0.8
"""The power at which the detectable difference is stated."""
COLUMNS = {"nasa_tlx": "scale_nasa_tlx", "trust": "scale_trust"}


def _values(
    plan: Preregistered, visits: Visits, scores: pd.DataFrame | None, name: str
) -> list[float]:
    if plan.measure == "comparable_score":
        if scores is None:
            return []
        chosen = scores.loc[scores["condition"] == name, "score"]
    else:
        people = participants(visits)
        column = COLUMNS.get(plan.measure, plan.measure)
        if column not in people:
            return []
        chosen = people.loc[people["condition"] == name, column]
    values = [float(v) for v in chosen.dropna()]
    return [math.log(v) for v in values if v > 0] if plan.measure == "median_decision_s" else values


def _counts(plan: Preregistered, visits: Visits, name: str) -> tuple[int, int]:
    if plan.measure == "completed":
        row = flow(visits).set_index("condition").loc[name]
        return int(row["completed"]), int(row["consented"])
    row = check_rates(visits).set_index("condition").loc[name]
    return int(row["passed"]), int(row["took"])


def primary_test(
    plan: Preregistered, visits: Visits, scores: pd.DataFrame | None, alpha: float
) -> tuple[Tested, float, float, int]:
    """The primary test, and the spreads (sd of a, of b) and the smaller group's size the
    power is stated for."""
    a, b = plan.conditions
    if MEASURES[plan.measure][1] == RATE:
        (got_a, of_a), (got_b, of_b) = _counts(plan, visits, a), _counts(plan, visits, b)
        tested = fisher(got_a, of_a, got_b, of_b, alpha)
        rates = [got / of if of else math.nan for got, of in ((got_a, of_a), (got_b, of_b))]
        spreads = [math.sqrt(r * (1 - r)) for r in rates]
        return tested, spreads[0], spreads[1], min(of_a, of_b)
    x, y = _values(plan, visits, scores, a), _values(plan, visits, scores, b)
    tested = mann_whitney(x, y, alpha) if plan.test == "mann_whitney" else welch(x, y, alpha)
    sd = [float(pd.Series(v).std()) if len(v) > 1 else math.nan for v in (x, y)]
    return tested, sd[0], sd[1], min(len(x), len(y))


def detectable(sd_a: float, sd_b: float, n: int, alpha: float, power: float = TARGET) -> float:
    """The difference the normal approximation detects with `power` at n per group."""
    z = stats.norm.ppf(1 - alpha / 2) + stats.norm.ppf(power)
    return float(z * math.sqrt((sd_a**2 + sd_b**2) / n))


def primary_lines(
    plan: Preregistered, visits: Visits, scores: pd.DataFrame | None, alpha: float
) -> list[str]:
    """The report's opening section: the primary test's result and the power it had."""
    a, b = plan.conditions
    tested, sd_a, sd_b, n = primary_test(plan, visits, scores, alpha)
    head = (
        f"Pre-registered in the study's design: {plan.words} ({plan.measure}), "
        f"{TEST_NAMES[plan.test]} between {a} and {b}, at α = {alpha:g}, uncorrected. "
        "Every other test in this report is exploratory."
    )
    if tested.no_test:
        result = f"No test yet: {tested.no_test} ({tested.n_a} in {a}, {tested.n_b} in {b})."
    else:
        verdict = "significant" if tested.p < alpha else "not significant"
        scale = " on the log scale" if plan.measure == "median_decision_s" else ""
        result = (
            f"{a}: {tested.n_a}, {b}: {tested.n_b}; statistic {tested.statistic:.3g}, "
            f"p = {tested.p:.3g}, {verdict}; {tested.effect}{scale} {tested.estimate:.3g} "
            f"[{tested.low:.3g}, {tested.high:.3g}]."
        )
    if n < 2 or math.isnan(sd_a) or math.isnan(sd_b):
        power = "No power can be stated yet: each condition needs two values with a spread."
    else:
        smallest = detectable(sd_a, sd_b, n, alpha)
        power = (
            f"Power for the observed spread (sd {sd_a:.3g} in {a}, {sd_b:.3g} in {b}; {n} per "
            f"condition, normal approximation): a difference of {smallest:.3g} was detectable "
            f"with {TARGET:.0%} power"
        )
        if plan.effect is not None:
            had = normal_power(plan.effect, sd_a, sd_b, n, alpha)
            power += (
                f"; the design's smallest effect worth detecting, {plan.effect:g}, with {had:.0%}"
            )
        power += "."
    return ["## Primary test (pre-registered)", "", head, "", result, "", power, ""]
