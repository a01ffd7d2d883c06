"""The comparability audit and the rescoring table in a report."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from analysis import write_report
from analysis.audit import audit, describe_learner
from analysis.rescoring import STEP_COLUMNS, rescored_schemes, rescored_totals, rescoring_table
from sim.rewards import REWARD_SCHEMES, step_penalty
from tests.analysis.test_report import study_episodes


def settings_for(episodes: pd.DataFrame, **by_method: dict[str, str]) -> pd.DataFrame:
    """One settings row per session: the paper's everything, changed per method."""
    rows = []
    for session_id, method in episodes.groupby("session_id")["method"].first().items():
        row = {
            "session_id": session_id, "method": method, "reward_scheme": "paper",
            "learner": "paper", "knock_off_rate": 0.0, "motion": "fast", "sort_rule": "color",
            "advice": "none" if method == "autonomous" else "early, budget 100",
        }  # fmt: skip
        row.update(by_method.get(method, {}))
        rows.append(row)
    return pd.DataFrame(rows)


@pytest.mark.slow
def test_same_settings_compare_and_keep_every_t_test(tmp_path: Path) -> None:
    episodes = study_episodes()
    result = write_report(episodes, tmp_path, settings=settings_for(episodes))
    assert result.audit is not None and result.audit.comparable
    assert result.analysis.t_tests["p"].notna().all()
    text = result.report.read_text()
    assert "Comparability warning" not in text and "They do here." in text


@pytest.mark.slow
def test_different_schemes_are_flagged_and_their_t_tests_withheld(tmp_path: Path) -> None:
    episodes = study_episodes()
    settings = settings_for(
        episodes,
        autonomous={"reward_scheme": "authors-autonomous"},
        agent={"reward_scheme": "authors-interactive"},
        human={"reward_scheme": "authors-interactive"},
    )
    result = write_report(episodes, tmp_path / "strict", settings=settings)
    text = result.report.read_text()
    first = text.split("\n\n")[1]
    assert first.startswith("> **Comparability warning.**")
    assert "autonomous DeepRL and agent-IDeepRL" in first and "reward scheme" in first
    tests = result.analysis.t_tests
    against_base = tests["method_b"].eq("autonomous") | tests["method_a"].eq("autonomous")
    assert tests.loc[against_base, "p"].isna().all()
    assert tests.loc[against_base, ["t_welch", "p_welch", "df_welch"]].isna().all().all()
    assert tests.loc[~against_base, "p_welch"].notna().all()
    assert (tests.loc[against_base, "withheld"].str.contains("reward scheme")).all()
    same_scheme = ~against_base  # agent vs human: both authors-interactive
    assert tests.loc[same_scheme, "p"].notna().all()
    csv = pd.read_csv(result.tables["t_tests"])
    assert csv.loc[csv["method_a"].eq("agent") & csv["method_b"].eq("autonomous"), "t"].isna().all()
    assert "t-test withheld" in text
    paper = result.analysis.paper.set_index("quantity")
    against = [q for q in paper.index if q.startswith(("|t|", "p ")) and "autonomous" in q]
    assert against and paper.loc[against, "ours"].isna().all()

    allowed = write_report(episodes, tmp_path / "allowed", settings=settings, allow_mismatch=True)
    assert allowed.analysis.t_tests["p"].notna().all()
    allowed_text = allowed.report.read_text()
    assert "Comparability warning" in allowed_text and "--allow-mismatch" in allowed_text


@pytest.mark.slow
def test_the_power_section_cautions_against_a_baseline_run_under_other_settings(
    tmp_path: Path,
) -> None:
    """Power plans for the observed effect; where the baseline ran under other settings that
    effect is not the treatment's, and the section says so for each such arm."""
    episodes = study_episodes()
    settings = settings_for(episodes, autonomous={"reward_scheme": "authors-autonomous"})
    result = write_report(episodes, tmp_path, settings=settings, power_draws=200)
    text = result.report.read_text()
    power = text.split("## Power")[1].split("\n## ")[0]
    for name in ("agent-IDeepRL", "human-IDeepRL"):
        assert (
            f"Caution: {name}'s baseline autonomous DeepRL ran under other settings "
            "(reward scheme)" in power
        ), power
    same = write_report(episodes, tmp_path / "same", settings=settings_for(episodes))
    assert "Caution" not in same.report.read_text().split("## Power")[1]


def _steps(episodes: pd.DataFrame, settings: pd.DataFrame) -> pd.DataFrame:
    """Three training steps an episode, a placement worth the episode's reward last, each
    other step costing what the session's scheme says."""
    schemes = dict(zip(settings["session_id"], settings["reward_scheme"], strict=True))
    rows = []
    for row in episodes.itertuples():
        scheme = schemes[row.session_id]
        for n in (1, 2):
            rows.append((row.session_id, row.episode, n, step_penalty(scheme, n), False, "none"))
        rows.append((row.session_id, row.episode, 3, row.collected_reward, True, "placed"))
    return pd.DataFrame(rows, columns=[*STEP_COLUMNS, "outcome"])


@pytest.mark.slow
def test_the_rescoring_table_withholds_what_one_scheme_does_not_make_comparable(
    tmp_path: Path,
) -> None:
    """Rescoring scores every run under one scheme, which removes a difference of scheme
    and no other: agent-IDeepRL also ran on another CPU kind than the baseline, so its
    Welch's p under each scheme is withheld (with the reason); human-IDeepRL keeps its."""
    episodes = study_episodes()
    settings = settings_for(
        episodes,
        autonomous={"reward_scheme": "authors-autonomous"},
        agent={"cpu_kind": "another CPU kind"},
    )
    settings["cpu_kind"] = settings["cpu_kind"].fillna("this CPU kind")
    result = write_report(
        episodes, tmp_path, settings=settings, steps=_steps(episodes, settings), power_draws=200
    )
    assert result.rescored is not None
    table = result.rescored.set_index("method")
    for scheme in REWARD_SCHEMES:
        assert np.isnan(table.loc["agent", f"p_welch_{scheme}"])
        assert table.loc["human", f"p_welch_{scheme}"] < 0.05
    assert table.loc["agent", "withheld"] == "the methods differ in CPU kind"
    text = result.report.read_text()
    rescoring = text.split("## R_T rescored under each reward scheme")[1].split("\n## ")[0]
    assert "withheld: the methods differ in CPU kind" in rescoring, rescoring
    allowed = write_report(
        episodes, tmp_path / "allowed", settings=settings, steps=_steps(episodes, settings),
        allow_mismatch=True, power_draws=200,
    )  # fmt: skip
    assert allowed.rescored is not None
    assert allowed.rescored.set_index("method")[f"p_welch_{REWARD_SCHEMES[0]}"].notna()["agent"]


def test_other_settings_and_mixed_methods_are_flagged() -> None:
    episodes = study_episodes()
    settings = settings_for(episodes, agent={"learner": "authors", "knock_off_rate": 0.05})
    settings.loc[settings.index[0], "motion"] = "physics"  # one autonomous session differs
    checked = audit(settings, "autonomous")
    assert checked.differ("autonomous", "agent") == [
        "learner preset and options", "knock off rate", "motion mode",
    ]  # fmt: skip
    assert checked.mixed == {"autonomous": ["motion mode"]}
    assert "differ among themselves" in " ".join(checked.warnings())
    assert checked.differ("agent", "human")[:2] == [
        "learner preset and options",
        "knock off rate",
    ]


def test_describe_learner_names_the_closest_preset() -> None:
    from learner.config import PRESETS, DQNConfig

    presets = {name: DQNConfig.preset(name).to_dict() for name in PRESETS}
    assert describe_learner(DQNConfig.preset("authors").to_dict(), presets) == "authors"
    assert describe_learner(DQNConfig(gamma=0.99, torch_threads=2).to_dict(), presets) == (
        "paper + gamma=0.99"
    )


def constructed_steps() -> tuple[pd.DataFrame, dict[int, str], dict[int, str]]:
    """Two sessions of one 25-step episode each (placements at steps 3, 6, 24 and a wrong
    one at 25, as in tests/sim/test_rewards.py), logged under two different schemes."""
    placed = {3: 0.4, 6: 0.4, 24: 0.4, 25: -1.0}
    rows = []
    schemes = {1: "authors-autonomous", 2: "authors-interactive"}
    for session_id, scheme in schemes.items():
        for n in range(1, 26):
            reward = placed.get(n, step_penalty(scheme, n))
            rows.append((session_id, 1, n, reward, n == 25))
    steps = pd.DataFrame(
        rows, columns=["session_id", "episode", "episode_step", "reward", "terminated"]
    )
    return steps, schemes, {1: "autonomous", 2: "agent"}


def test_rescored_r_t_of_a_constructed_episode() -> None:
    steps, schemes, methods = constructed_steps()
    totals = rescored_totals(steps, schemes).set_index("session_id")
    # by hand (see tests/sim/test_rewards.py): paper 0.15, autonomous 0.10, interactive -0.01
    for session_id in (1, 2):
        assert totals.loc[session_id, "R_T_paper"] == pytest.approx(0.15)
        assert totals.loc[session_id, "R_T_authors-autonomous"] == pytest.approx(0.10)
        assert totals.loc[session_id, "R_T_authors-interactive"] == pytest.approx(-0.01)
    assert totals.loc[1, "R_T_logged"] == pytest.approx(0.10)
    assert totals.loc[2, "R_T_logged"] == pytest.approx(-0.01)
    table = rescoring_table(totals.reset_index(), methods, "autonomous").set_index("method")
    # as logged, the same behaviour looks 110 % worse for agent; under one rule, equal
    assert table.loc["agent", "improvement_logged"] == pytest.approx(-110.0)
    assert table.loc["agent", "improvement_paper"] == pytest.approx(0.0)


def test_rescored_r_t_are_tested_under_each_scheme_with_welch() -> None:
    rng = np.random.default_rng(3)
    rows = []
    for session_id in range(1, 9):
        method = "autonomous" if session_id <= 4 else "agent"
        shift = 0.0 if method == "autonomous" else 10.0
        rows.append(
            {
                "session_id": session_id,
                "scheme": "paper",
                "R_T_logged": 0.0,
                **{
                    f"R_T_{s}": 100 + shift * k + rng.normal() for k, s in enumerate(REWARD_SCHEMES)
                },
            }
        )
    totals = pd.DataFrame(rows)
    methods = {i: ("autonomous" if i <= 4 else "agent") for i in range(1, 9)}
    table = rescoring_table(totals, methods, "autonomous").set_index("method")
    for scheme in REWARD_SCHEMES:
        column = f"R_T_{scheme}"
        expected = stats.ttest_ind(
            totals.loc[4:, column], totals.loc[:3, column], equal_var=False
        ).pvalue
        assert table.loc["agent", f"p_welch_{scheme}"] == pytest.approx(expected)
        assert np.isnan(table.loc["autonomous", f"p_welch_{scheme}"])
    # the first scheme has no shift, the last a large one
    assert table.loc["agent", f"p_welch_{REWARD_SCHEMES[-1]}"] < 0.001


@pytest.mark.slow
def test_a_study_of_another_task_is_audited_without_the_sorting_robots_settings(
    tmp_path: Path,
) -> None:
    """No session ran the sorting robot: its motion, rule and reward scheme are not audited
    (they mean nothing to the task), and R_T is rescored under the grid world's own schemes,
    never the robot's; a study that mixes tasks keeps the robot's settings and is rescored
    task by task (a task's schemes score only its own runs), the report saying which task
    was rescored under which schemes."""
    episodes = study_episodes()
    settings = settings_for(episodes).assign(task="gridworld")
    result = write_report(
        episodes, tmp_path / "grid", settings=settings, steps=_steps(episodes, settings),
        power_draws=200,
    )  # fmt: skip
    assert result.rescored is not None and result.audit is not None
    assert {"sort_rule", "motion", "reward_scheme"}.isdisjoint(result.audit.methods.columns)
    assert rescored_schemes(result.rescored) == ["minigrid", "sparse", "step-cost"]
    # each episode ends at its third step, the goal: sparse counts 1 an episode
    agents = episodes.groupby("method")["session_id"].nunique()
    per_method = episodes.groupby("method")["episode"].count() / agents
    table = result.rescored.set_index("method")
    assert table["R_T_sparse"].to_dict() == pytest.approx(per_method.to_dict())
    text = result.report.read_text()
    assert "sorting rule" not in text and "R_T under sparse" in text
    assert "authors-autonomous" not in text
    assert "| gridworld |" in text

    mixed = settings.assign(task=["sorting"] + ["gridworld"] * (len(settings) - 1))
    kept = write_report(
        episodes, tmp_path / "mixed", settings=mixed, steps=_steps(episodes, mixed),
        power_draws=200,
    )  # fmt: skip
    assert kept.rescored is not None and "sort_rule" in kept.audit.methods.columns
    table = kept.rescored
    robot = table[table["task"] == "sorting"].set_index("method")
    grid = table[table["task"] == "gridworld"].set_index("method")
    assert list(robot.index) == ["autonomous"] and robot.loc["autonomous", "agents"] == 1
    assert list(grid.index) == ["autonomous", "agent", "human"]
    assert grid["agents"].sum() == len(settings) - 1
    # each task's sessions under its own schemes; the other task's left empty
    assert robot.loc["autonomous", "R_T_paper"] == pytest.approx(
        robot.loc["autonomous", "R_T_logged"]
    )
    assert grid["R_T_paper"].isna().all() and robot["R_T_sparse"].isna().all()
    assert grid["R_T_sparse"].to_dict() == pytest.approx(per_method.to_dict())
    assert grid["improvement_sparse"].notna().all()  # against the grid world's baseline
    # within the grid world the methods differ in nothing: its tests are kept
    assert (grid["withheld"] == "").all() and grid["p_welch_minigrid"].notna()["agent"]
    agents_csv = pd.read_csv(kept.tables["rescored_agents"])
    assert set(agents_csv["undeclared"].dropna()) == {
        "minigrid, sparse, step-cost",
        ", ".join(REWARD_SCHEMES),
    }
    text = kept.report.read_text()
    rescoring = text.split("## R_T rescored under each reward scheme")[1].split("\n## ")[0]
    assert "different tasks" not in text and "| sorting |" in rescoring
    assert "gridworld under minigrid, sparse, step-cost" in rescoring, rescoring
    assert f"sorting under {', '.join(REWARD_SCHEMES)}" in rescoring
