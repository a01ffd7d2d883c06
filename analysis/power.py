"""How many participants a study needs: power of the per-agent Welch test on R_T.

A pilot gives each arm (method) a handful of R_T values. Planning the full study asks how
many agents per arm the report's primary test (Welch's two-sided t-test on the agents' R_T,
`analysis.stats.t_tests`) needs to detect the pilot's effect with 80 % or 90 %
probability. Two answers, because neither is safe alone with few pilot agents:

- **simulation** at the level of R_T: draw n agents per arm, run Welch's test, count the
  rejections over `draws` simulated studies; the agents are drawn either from the observed
  values themselves (`bootstrap`, keeps skew and outliers) or from a normal distribution
  with each arm's observed mean and sd (`fitted`, smooths a tiny pilot);
- **closed form**, the normal approximation of the two-sample test:
  n = (z_{1-alpha/2} + z_{power})^2 (sd_a^2 + sd_b^2) / delta^2 per arm, which with a
  common sd is the textbook 2 (z + z)^2 / d^2.

All of it is planning information about a future study, not a test of this one: the
effect and spreads are estimates from few agents, and the answers inherit their error.
Pure functions over numpy arrays; every random draw comes from a seeded `numpy` Generator,
one stream per (seed, n), so a number of agents gets the same simulated studies whether
the search or the plot asks for it, and results repeat exactly.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Literal

import numpy as np
from scipy import stats

Model = Literal["bootstrap", "fitted"]
MODELS: tuple[Model, ...] = ("bootstrap", "fitted")
"""How simulated agents are drawn: from the observed R_T values, or from a normal fit."""

TARGETS: tuple[float, ...] = (0.8, 0.9)
"""The powers a sample size is given for."""
DEFAULT_DRAWS = 2000
"""Simulated studies per number of agents: a power near 0.8 then has a Monte Carlo
standard error under 1 percentage point."""
MIN_AGENTS = 2
"""Agents an arm needs before its spread, and so any power, can be estimated."""
MIN_N = 2
"""The smallest study size searched: Welch's test needs two agents per arm."""
DEFAULT_MAX_N = 1000
"""The largest study size searched; an effect that needs more is reported as beyond it."""


def welch_rejects(a: np.ndarray, b: np.ndarray, alpha: float) -> np.ndarray:
    """Whether Welch's two-sided test rejects, for each row of two (studies, n) arrays.

    A study whose two arms are both constant is never a rejection: Welch's statistic is
    then 0/0 or d/0, undefined, and counting it as significant (t infinite) made the
    bootstrap from a small pilot report a false power spike at n = 2, where both arms
    often resample one value each (a pilot of 3 agents per arm: 1 study in 9). A real R_T
    is continuous and never gives such a study; the resampled population is discrete, so
    these draws say nothing about the test's power. "Constant" means every value of the
    row is equal (max == min), not a zero variance: the mean of equal floats can be off by
    an ulp, and the tiny variance left would give a huge t.
    A single constant arm beside a varying one is an ordinary Welch test (its variance is
    taken as exactly 0).
    """
    na, nb = a.shape[1], b.shape[1]
    flat_a = a.max(axis=1) == a.min(axis=1)
    flat_b = b.max(axis=1) == b.min(axis=1)
    va = np.where(flat_a, 0.0, a.var(axis=1, ddof=1)) / na
    vb = np.where(flat_b, 0.0, b.var(axis=1, ddof=1)) / nb
    diff = a.mean(axis=1) - b.mean(axis=1)
    se2 = va + vb
    defined = ~(flat_a & flat_b)
    safe = np.where(defined, se2, 1.0)
    t = diff / np.sqrt(safe)
    with np.errstate(divide="ignore", invalid="ignore"):
        dof = safe**2 / (va**2 / (na - 1) + vb**2 / (nb - 1))
    dof = np.where(np.isfinite(dof) & (dof > 0), dof, 1.0)
    p = 2.0 * stats.t.sf(np.abs(t), dof)
    return defined & (p < alpha)


def _draw(
    values: np.ndarray, n: int, draws: int, rng: np.random.Generator, model: Model
) -> np.ndarray:
    if model == "bootstrap":
        return rng.choice(values, size=(draws, n), replace=True)
    sd = float(values.std(ddof=1)) if len(values) > 1 else 0.0
    return rng.normal(float(values.mean()), sd, size=(draws, n))


def simulated_power(
    a: np.ndarray,
    b: np.ndarray,
    n: int,
    alpha: float = 0.05,
    draws: int = DEFAULT_DRAWS,
    rng: np.random.Generator | None = None,
    model: Model = "bootstrap",
) -> float:
    """Share of `draws` simulated studies, n agents per arm drawn from the observed R_T
    `a` and `b` (`model`: resampled, or a normal with each arm's mean and sd), in which
    Welch's two-sided test at `alpha` rejects equal means.

    A simulated study whose arms are both constant (likely at small n with `bootstrap`
    from a small pilot) counts as not significant: the test is undefined there
    (`welch_rejects`). Such studies stay in the denominator, so the power at n = 2 from a
    pilot of a few agents is low, as it should be, not a spike above alpha.
    """
    if n < MIN_N:
        raise ValueError(f"Welch's test needs at least {MIN_N} agents per arm, got n={n}")
    if draws < 1:
        raise ValueError(f"draws must be at least 1, got {draws}")
    if model not in MODELS:
        raise ValueError(f"unknown model {model!r}; use one of {', '.join(MODELS)}")
    rng = rng if rng is not None else np.random.default_rng()
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    rejects = welch_rejects(_draw(a, n, draws, rng, model), _draw(b, n, draws, rng, model), alpha)
    return float(rejects.mean())


def normal_power(delta: float, sd_a: float, sd_b: float, n: int, alpha: float = 0.05) -> float:
    """Power of the two-sided two-sample z-test with n per arm: Phi(|delta|/se - z) +
    Phi(-|delta|/se - z), se = sqrt((sd_a^2 + sd_b^2) / n), z = z_{1-alpha/2}.

    The closed form the sample-size formula inverts (it drops the second, tiny term); it
    ignores that the spreads are estimated, so it is optimistic for small n.
    """
    z = stats.norm.ppf(1 - alpha / 2)
    se = math.sqrt((sd_a**2 + sd_b**2) / n)
    if se == 0:
        return 1.0 if delta != 0 else alpha
    shift = abs(delta) / se
    return float(stats.norm.cdf(shift - z) + stats.norm.cdf(-shift - z))


def normal_sample_size(
    delta: float, sd_a: float, sd_b: float, power: float = 0.8, alpha: float = 0.05
) -> int | None:
    """Agents per arm by the normal approximation, rounded up:
    n = (z_{1-alpha/2} + z_{power})^2 (sd_a^2 + sd_b^2) / delta^2, at least `MIN_N`.

    None when there is no effect (delta = 0): no number of agents detects it.
    """
    if delta == 0:
        return None
    z = stats.norm.ppf(1 - alpha / 2) + stats.norm.ppf(power)
    exact = z**2 * (sd_a**2 + sd_b**2) / delta**2
    return max(MIN_N, math.ceil(exact - 1e-9))


def sample_size(
    power_at: Callable[[int], float],
    target: float,
    n_min: int = MIN_N,
    n_max: int = DEFAULT_MAX_N,
) -> int | None:
    """The smallest n in [n_min, n_max] with power_at(n) >= target, None if even n_max
    falls short.

    Takes power as nondecreasing in n (it is for the closed form and the exact test; a
    simulated power is so up to its Monte Carlo error, which can move the answer by an
    agent or two) and searches by doubling then bisection, so a simulation is run for
    about 2 log2(n) sizes rather than all of them.
    """
    if n_min > n_max:
        raise ValueError(f"n_min={n_min} is above n_max={n_max}")
    if power_at(n_min) >= target:
        return n_min
    low, high = n_min, n_min  # power_at(low) < target throughout
    while True:
        high = min(n_max, max(low + 1, 2 * low))
        if power_at(high) >= target:
            break
        if high == n_max:
            return None
        low = high
    while high - low > 1:
        middle = (low + high) // 2
        if power_at(middle) >= target:
            high = middle
        else:
            low = middle
    return high


@dataclass(frozen=True)
class SampleSize:
    """Agents per arm for one target power, by each method (None: more than `max_n`, or no
    effect to detect)."""

    target: float
    bootstrap: int | None
    fitted: int | None
    closed_form: int | None


@dataclass(frozen=True)
class PowerCurve:
    """Power against agents per arm, for the figure and the JSON output."""

    n: tuple[int, ...]
    bootstrap: tuple[float, ...]
    fitted: tuple[float, ...]
    closed_form: tuple[float, ...]


@dataclass(frozen=True)
class Comparison:
    """One arm against the baseline: the pilot's effect on R_T and the study it needs."""

    method: str
    baseline: str
    agents: int
    """The arm's agents in the pilot."""
    baseline_agents: int
    mean: float
    """The arm's mean R_T."""
    baseline_mean: float
    sd: float
    """Sample standard deviation (ddof=1) of the arm's R_T."""
    baseline_sd: float
    delta: float
    """mean - baseline_mean: the effect a future study is planned to detect."""
    d: float
    """Cohen's d: delta over the pooled sd sqrt((sd^2 + baseline_sd^2) / 2); NaN if 0/0."""
    sample_sizes: tuple[SampleSize, ...]
    curve: PowerCurve
    """Power on a grid of sizes up to a little beyond the largest n needed (the figure)."""
    at_sizes: PowerCurve = PowerCurve((), (), (), ())
    """Power at the sizes asked for (`at_n`): what a study of a given size can expect."""


@dataclass(frozen=True)
class PowerAnalysis:
    """The power analysis of a study's arms against its baseline."""

    baseline: str
    alpha: float
    draws: int
    """Simulated studies per number of agents."""
    seed: int
    max_n: int
    """The largest study size searched."""
    comparisons: tuple[Comparison, ...]
    skipped: tuple[str, ...] = field(default=())
    """Sentences on the arms left out and why (too few agents)."""

    def to_dict(self) -> dict[str, object]:
        """Plain JSON-able values (`ideeprl power --json`)."""
        return {
            "baseline": self.baseline,
            "alpha": self.alpha,
            "draws": self.draws,
            "seed": self.seed,
            "max_n": self.max_n,
            "test": "Welch's t-test, two-sided, on agents' R_T",
            "comparisons": [_jsonable(c) for c in self.comparisons],
            "skipped": list(self.skipped),
        }


def _jsonable(comparison: Comparison) -> dict[str, object]:
    out = asdict(comparison)
    out["d"] = comparison.d if math.isfinite(comparison.d) else None  # strict JSON
    for name in ("curve", "at_sizes"):
        out[name] = {k: list(v) for k, v in out[name].items()}
    return out


def _rng(seed: int, n: int, model: Model) -> np.random.Generator:
    """One stream per (seed, n, model): the search and the curve see the same studies."""
    return np.random.default_rng([seed, n, MODELS.index(model)])


def _curve_sizes(needed: Sequence[int | None], max_n: int, dense: int = 24) -> list[int]:
    """Sizes for the figure: every n up to `dense`, then powers of 2 and 1.5 times them up
    to a little beyond the largest n needed, the sizes the search has simulated already."""
    top = max([n for n in needed if n is not None], default=max_n)
    top = min(max_n, max(10, math.ceil(top * 1.25)))
    sizes = set(range(MIN_N, min(top, dense) + 1)) | {top}
    power = 1
    while power < top:
        sizes |= {n for n in (power, power * 3 // 2) if dense < n < top}
        power *= 2
    return sorted(sizes)


def compare(
    a: np.ndarray,
    b: np.ndarray,
    *,
    method: str,
    baseline: str,
    alpha: float = 0.05,
    draws: int = DEFAULT_DRAWS,
    seed: int = 0,
    targets: Sequence[float] = TARGETS,
    max_n: int = DEFAULT_MAX_N,
    at_n: Sequence[int] = (),
) -> Comparison:
    """The effect of arm `a` over baseline `b` and the agents per arm each target needs."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if min(len(a), len(b)) < MIN_AGENTS:
        raise ValueError(f"each arm needs at least {MIN_AGENTS} agents' R_T")
    sd_a, sd_b = float(a.std(ddof=1)), float(b.std(ddof=1))
    delta = float(a.mean() - b.mean())
    pooled = math.sqrt((sd_a**2 + sd_b**2) / 2)
    d = (
        delta / pooled
        if pooled > 0
        else (math.nan if delta == 0 else math.copysign(math.inf, delta))
    )
    cache: dict[tuple[Model, int], float] = {}

    def power(model: Model) -> Callable[[int], float]:
        def at(n: int) -> float:
            if (model, n) not in cache:
                cache[model, n] = simulated_power(
                    a, b, n, alpha, draws, _rng(seed, n, model), model
                )
            return cache[model, n]

        return at

    def closed(n: int) -> float:
        return normal_power(delta, sd_a, sd_b, n, alpha)

    sizes = tuple(
        SampleSize(
            target=float(target),
            bootstrap=sample_size(power("bootstrap"), target, MIN_N, max_n),
            fitted=sample_size(power("fitted"), target, MIN_N, max_n),
            closed_form=(
                None
                if (n := normal_sample_size(delta, sd_a, sd_b, target, alpha)) is None or n > max_n
                else n
            ),
        )
        for target in targets
    )

    def curve(sizes: Sequence[int]) -> PowerCurve:
        return PowerCurve(
            n=tuple(sizes),
            bootstrap=tuple(power("bootstrap")(n) for n in sizes),
            fitted=tuple(power("fitted")(n) for n in sizes),
            closed_form=tuple(closed(n) for n in sizes),
        )

    needed = [n for s in sizes for n in (s.bootstrap, s.fitted, s.closed_form)]
    return Comparison(
        method=method,
        baseline=baseline,
        agents=len(a),
        baseline_agents=len(b),
        mean=float(a.mean()),
        baseline_mean=float(b.mean()),
        sd=sd_a,
        baseline_sd=sd_b,
        delta=delta,
        d=d,
        sample_sizes=sizes,
        curve=curve(_curve_sizes(needed, max_n)),
        at_sizes=curve(at_n),
    )


def power_analysis(
    r_t: Mapping[str, np.ndarray],
    baseline: str,
    *,
    alpha: float = 0.05,
    draws: int = DEFAULT_DRAWS,
    seed: int = 0,
    targets: Sequence[float] = TARGETS,
    max_n: int = DEFAULT_MAX_N,
    at_n: Sequence[int] = (),
    progress: Callable[[str], None] | None = None,
) -> PowerAnalysis:
    """Every arm of `r_t` (method -> its agents' R_T) against `baseline`.

    An arm with fewer than `MIN_AGENTS` agents is left out with a sentence in `skipped`
    (a baseline with too few leaves every arm out), never an error: a pilot may be that
    small. `at_n` adds the power at these agents per arm (`Comparison.at_sizes`);
    `progress` hears a line before each comparison (each takes seconds).
    """
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be between 0 and 1, got {alpha}")
    if draws < 1:
        raise ValueError(f"draws must be at least 1, got {draws}")
    if any(not 0 < t < 1 for t in targets):
        raise ValueError(f"target powers must be between 0 and 1, got {list(targets)}")
    if any(n < MIN_N for n in at_n):
        raise ValueError(f"sizes must be at least {MIN_N} agents per arm, got {list(at_n)}")
    if baseline not in r_t:
        raise ValueError(f"baseline {baseline!r} is not an arm; arms: {', '.join(r_t)}")
    base = np.asarray(r_t[baseline], dtype=float)
    others = [m for m in r_t if m != baseline]
    skipped: list[str] = []
    if len(base) < MIN_AGENTS:
        skipped.append(
            f"the baseline {baseline} has {len(base)} agent(s); power needs at least "
            f"{MIN_AGENTS} per arm to estimate a spread"
        )
        others = []
    comparisons = []
    for i, method in enumerate(others, start=1):
        values = np.asarray(r_t[method], dtype=float)
        if len(values) < MIN_AGENTS:
            skipped.append(
                f"{method} has {len(values)} agent(s); power needs at least {MIN_AGENTS} "
                "per arm to estimate a spread"
            )
            continue
        if progress is not None:
            progress(f"{method} vs {baseline} ({i} of {len(others)})")
        comparisons.append(
            compare(
                values,
                base,
                method=method,
                baseline=baseline,
                alpha=alpha,
                draws=draws,
                seed=seed,
                targets=targets,
                max_n=max_n,
                at_n=at_n,
            )
        )
    return PowerAnalysis(baseline, alpha, draws, seed, max_n, tuple(comparisons), tuple(skipped))
