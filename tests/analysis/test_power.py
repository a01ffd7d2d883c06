"""Power analysis: the simulation against the exact power of the t-test, the closed form
against the textbook, the search for the smallest n, and `ideeprl power` on a real study."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy import stats

from analysis.formats import FIGURE_FORMATS_VARIABLE
from analysis.power import (
    normal_power,
    normal_sample_size,
    power_analysis,
    sample_size,
    simulated_power,
    welch_rejects,
)
from cli.main import main
from learner.run import RunSpec
from study.db.engine import make_engine, make_session_factory
from study.db.models import Status
from study.services.sessions import create_session
from study.services.studies import create_study
from tests.analysis.stored import migrated_folder, training_episode


def exact_power(d: float, n: int, alpha: float = 0.05) -> float:
    """Power of the two-sided two-sample t-test, n per arm, equal variances: the noncentral
    t with 2n - 2 degrees of freedom and noncentrality d sqrt(n / 2). With equal n and sd
    Welch's statistic is Student's; only its degrees of freedom differ, by well under 1 pp
    of power at these sizes."""
    dof = 2 * n - 2
    critical = stats.t.ppf(1 - alpha / 2, dof)
    shift = d * math.sqrt(n / 2)
    return float(stats.nct.sf(critical, dof, shift) + stats.nct.cdf(-critical, dof, shift))


def test_the_vectorised_welch_test_is_scipys() -> None:
    rng = np.random.default_rng(8)
    a, b = rng.normal(1.5, 1.0, (300, 5)), rng.normal(0.0, 2.0, (300, 7))
    p = stats.ttest_ind(a, b, axis=1, equal_var=False).pvalue
    assert 20 < (p < 0.05).sum() < 280, "both outcomes occur"
    assert (welch_rejects(a, b, 0.05) == (p < 0.05)).all()
    constant = np.ones((2, 3))
    assert welch_rejects(constant, np.vstack([2 * constant[0], constant[1]]), 0.05).tolist() == [
        False,
        False,
    ], "two constant arms: the test is undefined, whether or not the means differ"


@pytest.mark.filterwarnings("ignore:Precision loss:RuntimeWarning")  # scipy, constant arm
def test_two_constant_arms_are_no_rejection_even_off_by_an_ulp() -> None:
    """The mean of three 0.1s is not exactly 0.1, so their variance is ~3e-34, not 0: a
    zero-variance check alone would give t ~ 1e16 and a rejection."""
    a, b = np.full((1, 3), 0.1), np.full((1, 3), 0.2)
    assert a.var(axis=1, ddof=1)[0] > 0, "the premise: float error leaves a tiny variance"
    assert not welch_rejects(a, b, 0.05).any()
    for varying in ([0.15, 0.25, 0.3], [0.5, 0.52, 0.55]):
        p = stats.ttest_ind(a[0], varying, equal_var=False).pvalue
        assert welch_rejects(a, np.array([varying]), 0.05)[0] == (p < 0.05), (
            "one constant arm beside a varying one is an ordinary Welch test"
        )


@pytest.mark.parametrize("values", [[1.0, 2.0, 3.0], [0.1, 0.7, 0.3]])
def test_no_false_power_spike_at_two_agents(values: list[float]) -> None:
    """A zero effect from a pilot of 3 agents per arm: at n = 2 both bootstrap arms are
    constant in 1 study in 9, which used to count as significant (power ~0.13 at n = 2,
    ~0.03 at n = 3). Undefined studies are no rejection, so n = 2 is not above alpha nor
    above n = 3."""
    pilot = np.array(values)
    power = {
        n: simulated_power(pilot, pilot, n, 0.05, 4000, np.random.default_rng(n)) for n in (2, 3)
    }
    assert power[2] <= 0.05
    assert power[2] <= power[3]
    curve = power_analysis({"a": pilot, "b": pilot}, "b", draws=2000).comparisons[0].curve
    assert curve.n[0] == 2
    assert curve.bootstrap[0] <= 0.05
    assert curve.bootstrap[0] <= curve.bootstrap[1]


@pytest.mark.parametrize("model", ["bootstrap", "fitted"])
@pytest.mark.parametrize(("d", "n"), [(0.8, 20), (0.5, 40), (1.5, 6)])
def test_simulated_power_is_within_3_points_of_the_exact_power(
    model: str, d: float, n: int
) -> None:
    """Arms known to be normal (a large sample of each stands for the distribution)."""
    population = np.random.default_rng(5)
    a, b = population.normal(d, 1.0, 20_000), population.normal(0.0, 1.0, 20_000)
    simulated = simulated_power(a, b, n, 0.05, 4000, np.random.default_rng(1), model)  # type: ignore[arg-type]
    assert simulated == pytest.approx(exact_power(d, n), abs=0.03)
    again = simulated_power(a, b, n, 0.05, 4000, np.random.default_rng(1), model)  # type: ignore[arg-type]
    assert again == simulated, "the same seed gives the same simulated studies"


def test_simulated_power_without_an_effect_is_the_false_positive_rate() -> None:
    values = np.random.default_rng(2).normal(0.0, 1.0, 5000)
    rate = simulated_power(values, values, 10, 0.05, 4000, np.random.default_rng(3))
    assert rate == pytest.approx(0.05, abs=0.015)


def test_the_closed_form_is_the_textbook_value() -> None:
    """d = 0.5, alpha 0.05, power 0.8: 2 (1.959964 + 0.841621)^2 / 0.25 = 62.79, rounded up
    to 63 per arm (the normal approximation; the t-test itself needs 64, below)."""
    assert normal_sample_size(0.5, 1.0, 1.0, 0.8, 0.05) == 63
    assert normal_sample_size(-0.5, 1.0, 1.0, 0.8, 0.05) == 63
    assert normal_sample_size(1.0, 2.0, 2.0, 0.8, 0.05) == 63  # only d counts
    # Unequal spreads: (z + z)^2 (sd_a^2 + sd_b^2) / delta^2 = 7.8489 * 5 / 1 = 39.24 -> 40.
    assert normal_sample_size(1.0, 1.0, 2.0, 0.8, 0.05) == 40
    assert normal_sample_size(0.5, 1.0, 1.0, 0.9, 0.05) == 85  # 2 (1.959964 + 1.281552)^2 / 0.25
    assert normal_sample_size(0.0, 1.0, 1.0) is None
    # Power at n = 64: Phi(0.5 / sqrt(2 / 64) - 1.959964) = Phi(0.868463) = 0.80743, plus
    # Phi(-4.788391) = 8.4e-7 for the other side.
    assert normal_power(0.5, 1.0, 1.0, 64, 0.05) == pytest.approx(0.807430, abs=1e-6)
    n = normal_sample_size(0.5, 1.0, 1.0, 0.8, 0.05)
    assert n is not None and normal_power(0.5, 1.0, 1.0, n) >= 0.8 > normal_power(0.5, 1, 1, n - 1)


def test_the_search_returns_the_smallest_n_reaching_the_target() -> None:
    calls: list[int] = []

    def exact(n: int) -> float:
        calls.append(n)
        return exact_power(0.5, n)

    assert sample_size(exact, 0.8) == 64  # Cohen's table for d = 0.5
    assert exact_power(0.5, 64) >= 0.8 > exact_power(0.5, 63)
    assert len(calls) < 20, "doubling and bisection, not a scan"
    steps = [0.1 * n for n in range(11)]  # power n / 10: reaches 0.75 first at n = 8
    assert sample_size(lambda n: steps[min(n, 10)], 0.75, 2, 10) == 8
    assert sample_size(lambda n: steps[min(n, 10)], 0.2, 2, 10) == 2
    assert sample_size(lambda n: steps[min(n, 10)], 0.95, 2, 9) is None
    for target in (0.8, 0.9):
        for delta, sd_a, sd_b in ((0.3, 1.0, 1.5), (2.0, 1.0, 0.5)):
            found = sample_size(
                lambda n, delta=delta, sd_a=sd_a, sd_b=sd_b: normal_power(delta, sd_a, sd_b, n),
                target,
            )
            assert found is not None
            assert normal_power(delta, sd_a, sd_b, found) >= target
            assert found == 2 or normal_power(delta, sd_a, sd_b, found - 1) < target


def test_a_study_analysis_leaves_out_arms_too_small_and_says_why() -> None:
    r_t = {
        "autonomous": np.array([3.0, 5.0, 4.0, 6.0]),
        "agent": np.array([6.0, 8.0, 7.0, 7.5]),
        "human": np.array([9.0]),
    }
    result = power_analysis(r_t, "autonomous", draws=2000, seed=4)
    assert [c.method for c in result.comparisons] == ["agent"]
    assert result.skipped == (
        "human has 1 agent(s); power needs at least 2 per arm to estimate a spread",
    )
    agent = result.comparisons[0]
    assert agent.delta == pytest.approx(2.625)
    spreads = (np.std(r_t["agent"], ddof=1), np.std(r_t["autonomous"], ddof=1))
    assert (agent.sd, agent.baseline_sd) == pytest.approx(spreads)
    for size in agent.sample_sizes:
        assert size.closed_form == normal_sample_size(
            agent.delta, agent.sd, agent.baseline_sd, size.target
        )
        curve = dict(zip(agent.curve.n, agent.curve.bootstrap, strict=True))
        if size.bootstrap in curve:
            assert curve[size.bootstrap] >= size.target
    assert power_analysis(r_t, "autonomous", draws=2000, seed=4) == result, "reproducible"
    alone = power_analysis({"autonomous": np.array([1.0]), "agent": r_t["agent"]}, "autonomous")
    assert alone.comparisons == () and "the baseline autonomous has 1 agent(s)" in alone.skipped[0]


@pytest.fixture
def data_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A data folder whose database holds a finished pilot: 3 autonomous and 3 oracle-advised
    sessions with 4 recorded training episodes each, and one unfinished session."""
    folder, engine = migrated_folder(tmp_path, monkeypatch)
    rewards = {
        "autonomous": [[0.5, 1.0, 0.0, 1.5], [1.0, 0.5, 1.0, 0.5], [0.0, 1.5, 1.5, 1.0]],
        "oracle": [[1.5, 2.0, 1.5, 2.5], [2.0, 2.5, 2.0, 1.0], [1.0, 2.5, 2.5, 2.0]],
    }
    with make_session_factory(engine)() as db:
        study = create_study(db, "pilot", description="power")
        for method, runs in rewards.items():
            for seed, episodes in enumerate(runs):
                session = create_session(db, study.id, RunSpec(method=method, seed=seed))
                session.status = Status.finished.value
                for number, reward in enumerate(episodes, start=1):
                    db.add(training_episode(session.id, number, reward))
        create_session(db, study.id, RunSpec(method="oracle", seed=9))  # not finished: left out
        db.commit()
    engine.dispose()
    return folder


def test_the_command_prints_the_table_and_writes_the_figure(
    data_dir: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv(FIGURE_FORMATS_VARIABLE, raising=False)  # every format, by default
    flags = ["--data-dir", str(data_dir)]
    out = tmp_path / "power"
    assert main(["power", "--study", "pilot", "--out", str(out), "--seed", "7", *flags]) == 0
    printed = capsys.readouterr().out
    # R_T: autonomous 3.0, 3.0, 4.0; oracle 7.5, 7.5, 8.0 -> effect +4.33, sd 0.29 / 0.58,
    # d = 4.333 / sqrt((0.0833 + 0.3333) / 2) = 9.49.
    assert "oracle-IDeepRL vs autonomous DeepRL: effect +4.33 R_T (d = 9.49)" in printed
    assert "sd 0.29 / 0.58; pilot 3 + 3 agents" in printed
    assert "Left out 1 session not finished yet: session 7 (not started); wait until" in printed
    assert "Planning information, not a test." in printed
    assert "2000 simulated studies per size, seed 7" in printed
    rows = [
        line.split() for line in printed.splitlines() if line.lstrip().startswith(("80%", "90%"))
    ]
    assert [row[0] for row in rows] == ["80%", "90%"]
    assert all(row[3] == "2" for row in rows), "closed form: d = 9.5 needs the minimum"
    assert {p.name for p in out.iterdir()} == {"power.png", "power.svg", "power.pdf", "power.csv"}
    with Image.open(out / "power.png") as image:
        assert image.format == "PNG" and min(image.size) > 300
    assert "<svg" in (out / "power.svg").read_text()

    assert (
        main(["power", "--study", "pilot", "--json", "--seed", "7", "--n", "2", "5", *flags]) == 0
    )
    parsed = json.loads(capsys.readouterr().out)
    assert parsed["baseline"] == "autonomous" and parsed["draws"] == 2000
    assert parsed["n_episodes"] == 4 and len(parsed["sessions"]) == 6
    (oracle,) = parsed["comparisons"]
    assert oracle["method"] == "oracle" and oracle["delta"] == pytest.approx(13 / 3)
    assert [s["target"] for s in oracle["sample_sizes"]] == [0.8, 0.9]
    at = oracle["at_sizes"]
    assert at["n"] == [2, 5] and at["closed_form"][0] == pytest.approx(
        normal_power(13 / 3, math.sqrt(1 / 12), math.sqrt(1 / 3), 2)
    )
    curve = dict(zip(oracle["curve"]["n"], oracle["curve"]["bootstrap"], strict=True))
    assert at["bootstrap"] == [curve[2], curve[5]], "a size gets the same studies everywhere"
    rows_80 = next(r for r in rows if r[0] == "80%")
    assert str(oracle["sample_sizes"][0]["bootstrap"]) == rows_80[1], "same seed, same numbers"


def test_the_command_refuses_what_it_cannot_do(
    data_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    flags = ["--data-dir", str(data_dir)]
    assert main(["power", "--study", "no such study", *flags]) == 1
    assert "error: no study with name no such study; studies: 1 (pilot)" in capsys.readouterr().err
    assert main(["power", "--study", "pilot", "--alpha", "1.5", *flags]) == 2
    assert "alpha must be between 0 and 1" in capsys.readouterr().err
    assert main(["power", "--study", "pilot", "--draws", "10", *flags]) == 2
    assert "draws must be at least 100" in capsys.readouterr().err
    assert main(["power", "--study", "pilot", "--n", "1", *flags]) == 2
    assert "sizes must be 2 to max_n=1000 agents per arm, got 1" in capsys.readouterr().err
    assert main(["power", "--study", "pilot", "--baseline", "human", "--json", *flags]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and "no 'human' sessions" in captured.err
    (tmp_path / "file").write_text("")
    assert main(["power", "--study", "pilot", "--out", str(tmp_path / "file"), *flags]) == 2
    assert "is a file; pass a folder" in capsys.readouterr().err
    every = ["--sessions", *map(str, range(1, 8))]  # 7: created, never run
    assert main(["power", "--study", "pilot", *every, *flags]) == 1
    assert "session(s) 7 have no training episodes yet" in capsys.readouterr().err
    assert main(["power", "--study", "pilot", "--methods", "oracle", *flags]) == 2
    error = capsys.readouterr().err
    assert "the baseline autonomous DeepRL is not among --methods (oracle)" in error, error
    engine = make_engine(f"sqlite:///{data_dir / 'ideeprl.sqlite3'}")
    with make_session_factory(engine)() as db:
        few = create_study(db, "tiny pilot")
        for method in ("autonomous", "autonomous", "oracle"):
            session = create_session(db, few.id, RunSpec(method=method))
            session.status = Status.finished.value
            db.add(training_episode(session.id, 1, 1.0))
        db.commit()
    engine.dispose()
    assert main(["power", "--study", "tiny pilot", "--out", str(tmp_path / "p"), *flags]) == 1
    error = capsys.readouterr().err
    assert "too few sessions for a power analysis: oracle has 1 agent(s)" in error
    assert not (tmp_path / "p").exists()


def test_the_command_cautions_against_a_baseline_run_under_other_settings(
    data_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The pilot's autonomous sessions scored under the authors' autonomous scheme: the
    effect is the scheme's as much as the advice's, and the notes say so for the arm."""
    engine = make_engine(f"sqlite:///{data_dir / 'ideeprl.sqlite3'}")
    with make_session_factory(engine)() as db:
        study = create_study(db, "pilot, two schemes")
        for method, scheme in (("autonomous", "authors-autonomous"), ("oracle", "paper")):
            for seed in range(3):
                run = RunSpec(method=method, seed=seed).with_values({"reward_scheme": scheme})
                session = create_session(db, study.id, run)
                session.status = Status.finished.value
                better = 2.0 if method == "oracle" else 0.0
                for number in range(1, 3):
                    db.add(training_episode(session.id, number, seed + number + better))
        db.commit()
    engine.dispose()
    flags = ["--data-dir", str(data_dir)]
    assert main(["power", "--study", "pilot, two schemes", "--draws", "200", *flags]) == 0
    printed = capsys.readouterr().out
    assert (
        "note: Caution: oracle-IDeepRL's baseline autonomous DeepRL ran under other settings "
        "(reward scheme)" in printed
    ), printed
    assert main(["power", "--study", "pilot", "--draws", "200", *flags]) == 0
    assert "Caution" not in capsys.readouterr().out, "the same settings: no caution"
