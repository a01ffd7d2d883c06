"""The figures draw what the tables say, with the labels a reader needs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure
from matplotlib.text import Text
from PIL import Image

from analysis import (
    EpisodeTableError,
    correlation_matrix,
    plot_correlation,
    plot_epsilon,
    plot_individual_agents,
    plot_method_curves,
    save_figure,
)
from analysis.figures import (
    bands_window,
    epsilon_reaches,
    example_agents,
    pick_reference_agent,
    plot_confidence_bands,
    plot_cumulative_reward,
    plot_power,
    smooth,
)
from analysis.formats import FIGURE_FORMATS_VARIABLE, figure_formats
from analysis.power import power_analysis
from tests.analysis.helpers import HAND_CASE, episodes_from_curves


def test_figure_5_draws_each_methods_mean_with_a_band_where_there_is_spread() -> None:
    figure = plot_method_curves(episodes_from_curves(HAND_CASE))
    ax = figure.axes[0]
    lines = {line.get_label(): line for line in ax.get_lines()}
    assert list(lines) == [
        "autonomous DeepRL (n=2)",
        "agent-IDeepRL (n=2)",
        "human-IDeepRL (n=1)",
    ]
    assert list(lines["agent-IDeepRL (n=2)"].get_ydata()) == [1.5, 2.5, 3.0]
    assert lines["autonomous DeepRL (n=2)"].get_color() == "black"
    bands = [c for c in ax.collections if isinstance(c, PolyCollection)]
    assert len(bands) == 2  # a single human agent has no spread to shade
    assert ax.get_xlabel() == "episode"
    assert "collected reward" in ax.get_ylabel()
    assert "standard deviation" in ax.get_title()


def test_smoothing_is_a_trailing_mean_for_the_eye_only() -> None:
    assert list(smooth([0.0, 0.0, 3.0, 3.0], 2)) == [0.0, 0.0, 1.5, 3.0]
    assert list(smooth([1.0, 2.0], 1)) == [1.0, 2.0]
    with pytest.raises(ValueError, match="at least 1 episode"):
        smooth([1.0], 0)
    figure = plot_method_curves(episodes_from_curves(HAND_CASE), smoothing=2)
    agent = figure.axes[0].get_lines()[1]
    assert list(agent.get_ydata()) == [1.5, 2.0, 2.75]
    title = " ".join(figure.axes[0].get_title().split())  # long titles wrap onto lines
    assert "moving average over 2 episodes" in title


def test_figure_6_puts_agents_against_the_median_reference_with_their_gain() -> None:
    curves = dict(HAND_CASE) | {"DeepRL3": ("autonomous", [1.0, 1.0, 2.0])}
    table = episodes_from_curves(curves)
    assert pick_reference_agent(table) == "DeepRL3"  # R_T 3, 4, 5: the median is 4
    figure = plot_individual_agents(table, method="agent")
    labels = [line.get_label() for line in figure.axes[0].get_lines()]
    assert labels == [
        "agent-IDeepRL1 (R_T = 6.0, +50.0 %)",
        "agent-IDeepRL2 (R_T = 8.0, +100.0 %)",
        "DeepRL3, reference (R_T = 4.0)",
    ]
    *agents, reference = figure.axes[0].get_lines()
    assert reference.get_color() == "black"
    assert reference.get_linestyle() == "--", "the reference reads apart from the agents"
    assert all(reference.get_zorder() < agent.get_zorder() for agent in agents), "beneath"
    chosen = plot_individual_agents(
        table, method="agent", labels=["agent-IDeepRL2"], reference_label="DeepRL1"
    )
    assert [line.get_label() for line in chosen.axes[0].get_lines()] == [
        "agent-IDeepRL2 (R_T = 8.0, +166.7 %)",
        "DeepRL1, reference (R_T = 3.0)",
    ]
    with pytest.raises(EpisodeTableError, match="no agents of method 'oracle'"):
        plot_individual_agents(table, method="oracle")
    with pytest.raises(EpisodeTableError, match="no agent labelled 'nobody'"):
        plot_individual_agents(table, method="agent", reference_label="nobody")


def test_example_agents_span_lowest_median_and_highest_r_t() -> None:
    curves = {f"h{i}": ("human", [float(r)]) for i, r in enumerate([5, 1, 9, 3, 7, 2])}
    table = episodes_from_curves(curves)
    # R_T order: h1=1, h5=2, h3=3, h0=5, h4=7, h2=9 -> positions 0, 2 (rounded 2.5), 5
    assert example_agents(table, "human", 3) == ["h1", "h2", "h3"]
    assert example_agents(table, "human", 6) == ["h0", "h1", "h2", "h3", "h4", "h5"]


def test_figure_7_writes_every_value_in_its_cell() -> None:
    x = np.array([0.0, 1.0, 3.0, 2.0])
    table = episodes_from_curves(
        {"a": ("agent", x), "b": ("agent", -x), "c": ("human", np.ones(4))}
    )
    matrix = correlation_matrix(table)
    figure = plot_correlation(matrix)
    texts = [t.get_text() for t in figure.axes[0].texts]
    assert texts == ["1.00", "-1.00", "–", "-1.00", "1.00", "–", "–", "–", "–"]
    assert [t.get_text() for t in figure.axes[0].get_xticklabels()] == ["a", "b", "c"]
    assert "Pearson" in figure.axes[1].get_ylabel()  # the colour bar says what the colours mean
    assert len(plot_correlation(matrix, annotate=False).axes[0].texts) == 0


def test_epsilon_view_marks_when_exploration_reaches_one_percent() -> None:
    curves = {"a": ("autonomous", [0.0] * 4), "b": ("agent", [0.0] * 4)}
    epsilon = {"a": [0.5, 0.05, 0.01, 0.01], "b": [0.5, 0.4, 0.3, 0.2]}
    table = episodes_from_curves(curves, epsilon=epsilon)
    reached = epsilon_reaches(table)
    assert reached["autonomous"] == 3 and np.isnan(reached["agent"])
    labels = [line.get_label() for line in plot_epsilon(table).axes[0].get_lines()]
    assert labels[:2] == ["autonomous DeepRL, 1 % at episode 3", "agent-IDeepRL"]
    with pytest.raises(EpisodeTableError, match="no epsilon column"):
        plot_epsilon(episodes_from_curves(curves))


def test_save_figure_writes_a_png(tmp_path: Path) -> None:
    path = save_figure(
        plot_method_curves(episodes_from_curves(HAND_CASE)), tmp_path / "f.png", dpi=50
    )
    with Image.open(path) as image:
        assert image.format == "PNG"
        assert image.size == (450, 250)  # 9 x 5 inches at 50 dpi


def test_a_figure_is_written_in_the_formats_asked_for_and_always_as_png(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    figure = plot_method_curves(episodes_from_curves(HAND_CASE))
    monkeypatch.delenv(FIGURE_FORMATS_VARIABLE, raising=False)
    assert figure_formats() == ("png", "svg", "pdf")  # unset: every format
    monkeypatch.setenv(FIGURE_FORMATS_VARIABLE, " PDF, png ")
    assert figure_formats() == ("png", "pdf")
    assert figure_formats(["svg"]) == ("png", "svg")  # the argument before the environment
    save_figure(figure, tmp_path / "f.png", dpi=50)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.pdf", "f.png"]
    save_figure(figure, tmp_path / "g.png", dpi=50, formats="svg")
    assert sorted(p.name for p in tmp_path.glob("g.*")) == ["g.png", "g.svg"]

    with pytest.raises(ValueError, match=r"format\(s\) eps: the formats are png, svg, pdf"):
        figure_formats("png,eps")
    monkeypatch.setenv(FIGURE_FORMATS_VARIABLE, "jpg")
    with pytest.raises(ValueError, match="jpg"):
        save_figure(figure, tmp_path / "h.png")
    assert not list(tmp_path.glob("h.*")), "nothing is written in a mistaken format's stead"


def short_run() -> pd.DataFrame:
    """HAND_CASE, 3 episodes per agent, with an epsilon column."""
    epsilon = {label: [0.5, 0.1, 0.01] for label in HAND_CASE}
    return episodes_from_curves(HAND_CASE, epsilon=epsilon)


def short_run_figures() -> dict[str, Figure]:
    table = short_run()
    pilot = {"autonomous": np.array([3.0, 5.0, 4.0]), "agent": np.array([6.0, 8.0, 7.5])}
    return {
        "figure 5": plot_method_curves(table, smoothing=2),
        "figure 6": plot_individual_agents(table, method="agent"),
        "cumulative": plot_cumulative_reward(table),
        "bands": plot_confidence_bands(table),
        "epsilon": plot_epsilon(table),
        "power, one panel": plot_power(power_analysis(pilot, "autonomous", draws=100)),
    }


def titles(figure: Figure) -> list[Text]:
    found = [ax.title for ax in figure.axes if ax.title.get_text()]
    return found + [t for t in figure.texts if t.get_text()]  # a suptitle is a figure text


def test_every_title_fits_within_the_figure_width() -> None:
    """The bands figure's title and the one-panel power figure's suptitle used to be one
    line wider than the figure, cut off on both sides."""
    for name, figure in short_run_figures().items():
        figure.canvas.draw()
        renderer = figure.canvas.get_renderer()  # type: ignore[attr-defined]
        assert titles(figure), name
        for title in titles(figure):
            extent = title.get_window_extent(renderer)
            assert extent.x0 >= 0 and extent.x1 <= figure.bbox.width, (name, title.get_text())
    power = titles(short_run_figures()["power, one panel"])
    assert any("\n" in t.get_text() for t in power), "the one-panel suptitle is wrapped"


def test_a_short_title_stays_on_one_line() -> None:
    figure = plot_correlation(correlation_matrix(episodes_from_curves(HAND_CASE)))
    assert "\n" not in figure.axes[0].get_title()


def test_episode_axes_have_whole_number_ticks_on_a_short_run() -> None:
    """A 3-episode run was ticked at 1.25, 1.50, ... on Figures 5, 6 and epsilon."""
    for name, figure in short_run_figures().items():
        figure.canvas.draw()
        ticks = figure.axes[0].get_xticks()
        assert len(ticks) >= 2, name
        assert all(float(t).is_integer() for t in ticks), (name, list(ticks))


def test_the_bands_figure_draws_a_curve_on_a_run_shorter_than_its_window() -> None:
    """Three episodes under a 10-episode moving average left one point per method: no
    line, an x axis from 2.85 to 3.15. The window shrinks to half the run (here 1, the raw
    curve) and the title says so."""
    assert [bands_window(n) for n in (1, 2, 3, 5, 12, 20, 300)] == [1, 1, 1, 2, 6, 10, 10]
    ax = plot_confidence_bands(short_run()).axes[0]
    lines = ax.get_lines()
    assert len(lines) == 3
    for line in lines:
        assert list(line.get_xdata()) == [1, 2, 3]
    assert list(lines[1].get_ydata()) == [1.5, 2.5, 3.0]  # the agent arm's raw mean
    low, high = ax.get_xlim()
    assert low <= 1 and high >= 3
    assert "moving average" not in ax.get_title()
    long = plot_confidence_bands(episodes_from_curves({"a": ("autonomous", [1.0] * 30)}))
    assert len(long.axes[0].get_lines()[0].get_xdata()) == 21
    assert "moving average over 10 episodes" in " ".join(long.axes[0].get_title().split())


def test_the_bands_figure_marks_a_one_episode_run_as_points() -> None:
    one = {"a": ("autonomous", [1.0]), "b": ("autonomous", [2.0])}
    ax = plot_confidence_bands(episodes_from_curves(one)).axes[0]
    assert ax.get_lines()[0].get_marker() == "o"
    assert list(ax.get_lines()[0].get_ydata()) == [1.5]
