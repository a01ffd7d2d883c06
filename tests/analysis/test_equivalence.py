"""Two one-sided tests: against the interval they must agree with, and on the edge cases."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from analysis.equivalence import paired_tost, relative_margin


def test_tost_agrees_with_its_confidence_interval_and_with_scipy() -> None:
    rng = np.random.default_rng(3)
    a = rng.normal(100.0, 10.0, 10)
    b = a + rng.normal(0.5, 1.0, 10)
    result = paired_tost(a, b, margin=3.0)
    d = b - a
    # scipy's one-sided paired tests against a shifted mean give the same two p-values
    lower = stats.ttest_1samp(d, -3.0, alternative="greater").pvalue
    upper = stats.ttest_1samp(d, 3.0, alternative="less").pvalue
    assert result.p_value == pytest.approx(max(lower, upper))
    low, high = result.interval
    assert result.equivalent == (low > -3.0 and high < 3.0)
    assert result.equivalent
    assert low < d.mean() < high


def test_a_shift_beyond_the_margin_is_not_equivalent() -> None:
    a = np.arange(10.0)
    b = a + 5.0 + np.linspace(-0.1, 0.1, 10)
    result = paired_tost(a, b, margin=3.0)
    assert not result.equivalent and result.p_value > 0.5
    assert "not shown equivalent" in result.sentence()


def test_identical_pairs_are_equivalent_exactly_and_say_so() -> None:
    a = [-120.0, -80.5, -99.0]
    result = paired_tost(a, list(a), margin=relative_margin(a, 0.03))
    assert result.identical and result.equivalent and result.p_value == 0.0
    assert result.margin == pytest.approx(0.03 * 99.8333, rel=1e-4)  # |mean| of a negative arm
    assert "every pair identical" in result.sentence()
    shifted = paired_tost(a, [x + 10 for x in a], margin=3.0)  # constant shift, outside
    assert not shifted.identical and not shifted.equivalent and shifted.p_value == 1.0


@pytest.mark.parametrize(
    ("a", "b", "margin"),
    [([1.0], [1.0], 1.0), ([1.0, 2.0], [1.0], 1.0), ([1.0, np.nan], [1.0, 2.0], 1.0),
     ([1.0, 2.0], [1.0, 2.0], 0.0), ([1.0, 2.0], [1.0, 2.0], float("nan"))],
)  # fmt: skip
def test_bad_samples_or_margins_are_refused(a, b, margin) -> None:
    with pytest.raises(ValueError):
        paired_tost(a, b, margin)
