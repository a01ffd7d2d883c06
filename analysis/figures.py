"""The paper's figures (5, 6, 7) and two views that help read them.

Figures are built as `matplotlib.figure.Figure` objects, never through pyplot: the
dashboard renders them from server threads, and pyplot's global state is not
thread-safe. Saving a PNG goes through the Agg canvas, so no display is needed.
Smoothing is for the eye only: a trailing moving average, off by default, never applied
to the statistics.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.backend_bases import RendererBase
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Text
from matplotlib.ticker import FuncFormatter, MaxNLocator

from analysis.episodes import (
    EpisodeTableError,
    agents_of,
    method_name,
    order_methods,
    validate_episodes,
)
from analysis.formats import figure_formats
from analysis.power import PowerAnalysis
from analysis.stats import agent_totals, improvement_pct

METHOD_COLORS: dict[str, str] = {
    "autonomous": "black",
    "agent": "tab:blue",
    "human": "tab:red",
    "oracle": "tab:green",
    "random": "tab:gray",
    "sb3-dqn": "tab:purple",
    "fitted": "tab:orange",
}
"""The paper's colours (black, blue, red), three more for our extra advisors and one for
Stable-Baselines3's DQN."""

_SPARE_COLORS = ("tab:brown", "tab:pink", "tab:olive", "tab:cyan")
_AGENT_COLORS = (
    "tab:orange",
    "tab:green",
    "gold",
    "tab:purple",
    "tab:cyan",
    "tab:brown",
    "tab:pink",
    "tab:olive",
    "tab:blue",
    "tab:red",
    "tab:gray",
)


def method_color(method: str, methods: Sequence[str] = ()) -> str:
    """A stable colour per method; unknown methods take spare colours in order."""
    if method in METHOD_COLORS:
        return METHOD_COLORS[method]
    unknown = [m for m in methods if m not in METHOD_COLORS]
    index = unknown.index(method) if method in unknown else 0
    return _SPARE_COLORS[index % len(_SPARE_COLORS)]


def smooth(values: np.ndarray | pd.Series, window: int = 1) -> np.ndarray:
    """Trailing moving average over `window` episodes (1 = unchanged)."""
    if window < 1:
        raise ValueError(f"smoothing window must be at least 1 episode, got {window}")
    series = pd.Series(np.asarray(values, dtype=float))
    return series.rolling(window, min_periods=1).mean().to_numpy()


def _smoothing_note(window: int) -> str:
    return "" if window == 1 else f" (moving average over {window} episodes)"


def _new_figure(width: float = 9.0, height: float = 5.0) -> tuple[Figure, Axes]:
    figure = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(figure)
    return figure, figure.add_subplot()


def _integer_ticks(ax: Axes) -> None:
    """Whole-number ticks on an x axis that counts episodes or agents: a 3-episode run
    would otherwise be ticked at 1.25, 1.50, ..."""
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))


_TITLE_SHARE = 0.94
"""The share of its width (the figure's, or one panel's) a title may take: the rest is
the layout's padding."""


def _wrap_to(text: Text, width: float, renderer: RendererBase) -> None:
    """Break `text` into lines (textwrap, at spaces) until it is at most `width` pixels
    wide; a single word wider than that is left as it is."""
    lines = text.get_text().split("\n")
    chars = max(len(line) for line in lines)
    while chars > 8 and text.get_window_extent(renderer).width > width:
        # the next try: shrink the line length in proportion to the overflow, at least 1
        estimate = int(chars * width / text.get_window_extent(renderer).width)
        chars = max(8, min(chars - 1, estimate))
        text.set_text("\n".join(textwrap.fill(line, chars) for line in lines))


def fit_titles(figure: Figure, suptitle: Text | None = None) -> Figure:
    """Wrap every axes title, and `suptitle` (the figure's, as `Figure.suptitle` returned
    it), onto more lines where one line is wider than its space, so no title is clipped at
    the figure's edges: a title is centred on its axes and a line wider than the figure is
    cut on both sides, which constrained layout does not prevent. An axes title gets its
    grid cell's width (a panel of a several-panel figure), a suptitle the figure's.
    Returns the figure."""
    canvas = figure.canvas if isinstance(figure.canvas, FigureCanvasAgg) else None
    renderer = (canvas or FigureCanvasAgg(figure)).get_renderer()
    full = figure.bbox.width
    for ax in figure.axes:
        spec = ax.get_subplotspec()
        share = 1.0 if spec is None else spec.colspan.stop - spec.colspan.start
        columns = 1 if spec is None else spec.get_gridspec().ncols
        if ax.title.get_text():
            _wrap_to(ax.title, _TITLE_SHARE * full * share / columns, renderer)
    if suptitle is not None and suptitle.get_text():
        _wrap_to(suptitle, _TITLE_SHARE * full, renderer)
    return figure


_UNDATED = {"svg": {"Date": None}, "pdf": {"CreationDate": None}}
"""The metadata each vector format is saved with: no date, so a figure's files repeat."""


def save_figure(
    figure: Figure,
    path: str | Path,
    *,
    dpi: int = 150,
    formats: str | Sequence[str] | None = None,
) -> Path:
    """Write a figure as PNG, and in the other `formats` (`figure_formats`: by default SVG
    and PDF) beside it under the same name, and return the PNG's path (`vector_paths`
    gives the others). SVG and PDF carry no date, and SVG a fixed id salt, so the same
    figure gives the same files."""
    path = Path(path)
    vectors = vector_paths(path, formats)
    figure.savefig(path, dpi=dpi, format="png")
    # the layout the PNG was drawn with, kept for the vector files: constrained layout
    # would lay the same figure out again for each (a sixth of a figure's saving time)
    if vectors and figure.get_layout_engine() is not None:
        figure.set_layout_engine("none")
    with matplotlib.rc_context({"svg.hashsalt": "ideeprl"}):
        for vector in vectors:
            kind = vector.suffix.removeprefix(".")
            figure.savefig(vector, format=kind, metadata=_UNDATED[kind])
    return path


def vector_paths(png: Path, formats: str | Sequence[str] | None = None) -> tuple[Path, ...]:
    """The other files `save_figure` writes beside a figure's PNG in these `formats`
    (`figure_formats`)."""
    return tuple(png.with_suffix(f".{kind}") for kind in figure_formats(formats) if kind != "png")


def plot_method_curves(
    episodes: pd.DataFrame, *, baseline: str | None = "autonomous", smoothing: int = 1
) -> Figure:
    """Figure 5: average collected reward per episode per method, with a ±1 std band."""
    table = validate_episodes(episodes)
    figure, ax = _new_figure()
    methods = order_methods(table["method"], baseline)
    for method in methods:
        rows = table[table["method"] == method]
        stats = rows.groupby("episode")["collected_reward"].agg(["mean", "std", "count"])
        mean = smooth(stats["mean"], smoothing)
        std = smooth(stats["std"].fillna(0.0), smoothing)
        color = method_color(method, methods)
        n = int(stats["count"].iloc[0])
        ax.plot(stats.index, mean, color=color, lw=1.6, label=f"{method_name(method)} (n={n})")
        if n > 1:
            ax.fill_between(stats.index, mean - std, mean + std, color=color, alpha=0.18, lw=0)
    ax.set_title(
        "Average collected reward per episode, shaded ±1 standard deviation across agents"
        + _smoothing_note(smoothing)
    )
    ax.set_xlabel("episode")
    ax.set_ylabel("collected reward per episode (sum of step rewards)")
    _integer_ticks(ax)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    return fit_titles(figure)


BANDS_WINDOW = 10
"""The moving average of the bootstrap-band figure on a long run, in episodes."""


def bands_window(n_episodes: int, window: int = BANDS_WINDOW) -> int:
    """The moving average the bootstrap-band figure uses on a run of `n_episodes`: `window`,
    but at most half the episodes (at least 1, the raw curve), so the smoothed curve keeps
    more than half its points. A full window on a short run leaves one point per method,
    a line that draws nothing."""
    if window < 1:
        raise ValueError(f"smoothing window must be at least 1 episode, got {window}")
    return max(1, min(window, n_episodes // 2))


def plot_confidence_bands(
    episodes: pd.DataFrame,
    *,
    baseline: str | None = "autonomous",
    window: int = BANDS_WINDOW,
    resamples: int = 2000,
    seed: int = 0,
) -> Figure:
    """Each method's mean collected reward per episode (a moving average over `window`
    episodes) with a 95 % percentile bootstrap band over its agents, as `rliable` draws
    sample-efficiency curves: the band says how sure the mean is, where Figure 5's ±1
    standard deviation says how much agents differ.

    On a short run the window shrinks to half the episodes (`bands_window`; the title says
    which); a run of one episode is drawn as points, with no band to draw between them."""
    table = validate_episodes(episodes)
    figure, ax = _new_figure()
    methods = order_methods(table["method"], baseline)
    rng = np.random.default_rng(seed)
    shortest = int(table.groupby("method")["episode"].nunique().min())
    window = bands_window(shortest, window)
    kernel = np.ones(window) / window
    for method in methods:
        rows = table[table["method"] == method]
        curves = rows.pivot(index="session_id", columns="episode", values="collected_reward")
        values = curves.to_numpy(dtype=float)
        smoothed = np.array([np.convolve(v, kernel, mode="valid") for v in values])
        x = curves.columns.to_numpy()[len(kernel) - 1 :]
        color = method_color(method, methods)
        n = len(values)
        ax.plot(
            x,
            smoothed.mean(axis=0),
            color=color,
            lw=1.6,
            marker="o" if len(x) == 1 else None,
            label=f"{method_name(method)} (n={n})",
        )
        if n > 1:
            picks = rng.integers(0, n, size=(resamples, n))
            means = smoothed[picks].mean(axis=1)
            low, high = np.percentile(means, [2.5, 97.5], axis=0)
            ax.fill_between(x, low, high, color=color, alpha=0.22, lw=0)
    ax.set_title(
        "Mean collected reward per episode"
        + (f" (moving average over {window} episodes)" if window > 1 else "")
        + ", shaded: 95 % bootstrap interval of the mean over agents"
    )
    ax.set_xlabel("episode")
    ax.set_ylabel("collected reward per episode")
    _integer_ticks(ax)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    return fit_titles(figure)


def pick_reference_agent(episodes: pd.DataFrame, method: str = "autonomous") -> str:
    """The agent of `method` whose R_T is the median one: a typical agent to compare with."""
    totals = agent_totals(episodes, baseline=None)
    totals = totals[totals["method"] == method].sort_values(["R_T", "label"])
    if totals.empty:
        raise EpisodeTableError(f"no agent of method {method!r} to use as the reference")
    return str(totals["label"].iloc[(len(totals) - 1) // 2])


def example_agents(episodes: pd.DataFrame, method: str, count: int = 3) -> list[str]:
    """A few agents of `method` that span its range: lowest, median and highest R_T.

    The paper's Figure 6 shows three example human-advised agents; all of ten or more
    would hide each other. With `count` agents or fewer, all of them, in table order.
    """
    totals = agent_totals(episodes, baseline=None)
    totals = totals[totals["method"] == method].reset_index(drop=True)
    if len(totals) <= count:
        return list(totals["label"])
    ranked = totals.sort_values(["R_T", "label"]).reset_index()
    picks = np.linspace(0, len(ranked) - 1, count).round().astype(int)
    chosen = set(ranked.loc[picks, "index"])
    return [label for i, label in enumerate(totals["label"]) if i in chosen]


def plot_individual_agents(
    episodes: pd.DataFrame,
    *,
    method: str = "human",
    labels: Sequence[str] | None = None,
    reference_label: str | None = None,
    reference_method: str = "autonomous",
    smoothing: int = 1,
) -> Figure:
    """Figure 6: agents of one method, each against one reference (autonomous) agent.

    `labels` picks the agents (default: all agents of `method`). The legend gives each
    agent's R_T and its improvement over the reference agent's R_T, the way the paper
    quotes +126.85 %, +110.99 % and +136.94 %. The reference defaults to the median agent
    of `reference_method` (`pick_reference_agent`).
    """
    table = validate_episodes(episodes)
    if method not in set(table["method"]):
        raise EpisodeTableError(
            f"no agents of method {method!r}; methods present: "
            f"{', '.join(order_methods(table['method']))}"
        )
    totals = agent_totals(table, baseline=None).set_index("label")
    if reference_label is None:
        reference_label = pick_reference_agent(table, reference_method)
    if labels is None:
        labels = list(agents_of(table).query("method == @method")["label"])
    unknown = [label for label in [*labels, reference_label] if label not in totals.index]
    if unknown:
        raise EpisodeTableError(
            f"no agent labelled {', '.join(map(repr, unknown))}; "
            f"pick from {', '.join(totals.index)}"
        )
    reference_total = float(totals.loc[reference_label, "R_T"])
    figure, ax = _new_figure(9.0, 5.5)
    for i, label in enumerate(labels):
        rows = table[table["label"] == label]
        total = float(totals.loc[label, "R_T"])
        gain = (
            f"{improvement_pct(total, reference_total):+.1f} %"
            if reference_total > 0  # a percentage of a negative score misleads
            else f"{total - reference_total:+.1f} points"
        )
        ax.plot(
            rows["episode"],
            smooth(rows["collected_reward"], smoothing),
            color=_AGENT_COLORS[i % len(_AGENT_COLORS)],
            lw=1.1,
            label=f"{label} (R_T = {totals.loc[label, 'R_T']:.1f}, {gain})",
        )
    rows = table[table["label"] == reference_label]
    ax.plot(
        rows["episode"],
        smooth(rows["collected_reward"], smoothing),
        color="black",
        lw=1.6,
        ls="--",
        zorder=1.5,  # beneath the agents (lines draw at 2): they are what the figure shows
        label=f"{reference_label}, reference (R_T = {reference_total:.1f})",
    )
    ax.set_title(
        f"Collected reward of {method_name(method)} agents against {reference_label}"
        + _smoothing_note(smoothing)
    )
    ax.set_xlabel("episode")
    ax.set_ylabel("collected reward per episode (sum of step rewards)")
    _integer_ticks(ax)
    ax.grid(alpha=0.3)
    figure.legend(loc="outside lower center", fontsize="small", ncols=2 if len(labels) > 1 else 1)
    return fit_titles(figure)


def plot_correlation(matrix: pd.DataFrame, *, annotate: bool | None = None) -> Figure:
    """Figure 7: Pearson's correlation between agents' reward curves, values written in.

    `annotate` defaults to writing the values when there are at most 30 agents.
    """
    n = len(matrix)
    annotate = n <= 30 if annotate is None else annotate
    size = min(4.0 + 0.45 * n, 18.0)
    figure, ax = _new_figure(size + 1.5, size)
    image = ax.imshow(matrix.to_numpy(dtype=float), cmap="RdBu_r", vmin=-1.0, vmax=1.0)
    ax.set_xticks(range(n), [str(c) for c in matrix.columns], rotation=60, ha="right")
    ax.set_yticks(range(n), [str(i) for i in matrix.index])
    if annotate:
        fontsize = max(5.0, min(10.0, 120.0 / max(n, 1)))
        for (i, j), value in np.ndenumerate(matrix.to_numpy(dtype=float)):
            text = "–" if np.isnan(value) else f"{value:.2f}"
            color = "white" if abs(value) > 0.6 else "black"
            ax.text(j, i, text, ha="center", va="center", fontsize=fontsize, color=color)
    ax.set_title("Pearson's correlation between agents' collected reward per episode")
    ax.set_xlabel("agent")
    ax.set_ylabel("agent")
    figure.colorbar(image, ax=ax, shrink=0.8, label="Pearson's r (unitless, -1 to 1)")
    return fit_titles(figure)


def plot_cumulative_reward(
    episodes: pd.DataFrame, *, baseline: str | None = "autonomous"
) -> Figure:
    """Cumulative collected reward per method (mean ± 1 std); the last point is R_T."""
    table = validate_episodes(episodes).copy()
    table["cumulative"] = table.groupby("session_id")["collected_reward"].cumsum()
    figure, ax = _new_figure()
    methods = order_methods(table["method"], baseline)
    for method in methods:
        stats = (
            table[table["method"] == method].groupby("episode")["cumulative"].agg(["mean", "std"])
        )
        color = method_color(method, methods)
        mean, std = stats["mean"].to_numpy(), stats["std"].fillna(0.0).to_numpy()
        ax.plot(
            stats.index,
            mean,
            color=color,
            lw=1.6,
            label=f"{method_name(method)} (R_T = {mean[-1]:.1f})",
        )
        ax.fill_between(stats.index, mean - std, mean + std, color=color, alpha=0.15, lw=0)
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.set_title("Cumulative collected reward, mean ±1 std across agents (last point = R_T)")
    ax.set_xlabel("episode")
    ax.set_ylabel("cumulative collected reward (sum over episodes)")
    _integer_ticks(ax)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left")
    return fit_titles(figure)


def epsilon_reaches(episodes: pd.DataFrame, level: float = 0.01) -> pd.Series:
    """Per method: the first episode whose mean epsilon is at or below `level` (NaN: never)."""
    table = validate_episodes(episodes)
    if "epsilon" not in table:
        raise EpisodeTableError("the episode table has no epsilon column")
    mean = table.groupby(["method", "episode"], sort=False)["epsilon"].mean()
    reached = {}
    for method in order_methods(table["method"]):
        curve = mean.loc[method]
        below = curve.index[curve.to_numpy() <= level + 1e-12]
        reached[method] = float(below[0]) if len(below) else float("nan")
    return pd.Series(reached, name=f"first episode with epsilon <= {level}")


def plot_epsilon(episodes: pd.DataFrame, *, baseline: str | None = "autonomous") -> Figure:
    """Exploration rate epsilon per episode per method, with the 1 % level marked."""
    table = validate_episodes(episodes)
    if "epsilon" not in table:
        raise EpisodeTableError("the episode table has no epsilon column to plot")
    figure, ax = _new_figure(9.0, 4.0)
    methods = order_methods(table["method"], baseline)
    reached = epsilon_reaches(table)
    for method in methods:
        curve = table[table["method"] == method].groupby("episode")["epsilon"].mean()
        when = reached[method]
        note = "" if np.isnan(when) else f", 1 % at episode {int(when)}"
        color = method_color(method, methods)
        ax.plot(curve.index, curve.to_numpy() * 100, color=color, label=method_name(method) + note)
    ax.axhline(1.0, color="0.4", ls="--", lw=0.8)
    ax.set_yscale("log")  # so that the approach to the 1 % floor stays visible
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.set_title("Exploration: epsilon at the end of each episode (mean across agents)")
    ax.set_xlabel("episode")
    ax.set_ylabel("epsilon (% random actions, log scale)")
    _integer_ticks(ax)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right")
    return fit_titles(figure)


def plot_power(analysis: PowerAnalysis) -> Figure:
    """Power of Welch's test on R_T against agents per arm, one panel per comparison with
    the baseline: simulated from the observed R_T (bootstrap), from a normal fit, and the
    closed form, with the 80 % and 90 % lines where a planned study aims."""
    if not analysis.comparisons:
        raise EpisodeTableError("no comparison to plot: every arm has too few agents")
    count = len(analysis.comparisons)
    columns = min(count, 3)
    rows = -(-count // columns)
    figure = Figure(figsize=(4.6 * columns, 3.8 * rows), layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.subplots(rows, columns, squeeze=False).ravel()
    methods = [analysis.baseline, *(c.method for c in analysis.comparisons)]
    for ax, comparison in zip(axes, analysis.comparisons, strict=False):
        curve = comparison.curve
        color = method_color(comparison.method, methods)
        percent = [[100 * p for p in values] for values in
                   (curve.bootstrap, curve.fitted, curve.closed_form)]  # fmt: skip
        ax.plot(curve.n, percent[0], color=color, lw=1.8, marker=".", label="simulated: bootstrap")
        ax.plot(curve.n, percent[1], color=color, lw=1.2, ls="--", label="simulated: normal fit")
        ax.plot(curve.n, percent[2], color="0.3", lw=1.2, ls=":", label="closed form (normal)")
        for level in (80, 90):
            ax.axhline(level, color="0.5", lw=0.8, ls="-.")
            ax.annotate(
                f"{level} %",
                (0, level),
                xycoords=("axes fraction", "data"),
                xytext=(3, 2),
                textcoords="offset points",
                fontsize=8,
                color="0.4",
            )
        ax.set_ylim(0, 101)
        ax.set_title(
            f"{method_name(comparison.method)} vs {method_name(comparison.baseline)}\n"
            f"effect {comparison.delta:+.2f} R_T, d = {comparison.d:.2f}",
            fontsize=10,
        )
        ax.set_xlabel("agents (participants) per arm")
        ax.set_ylabel("power (%)")
        _integer_ticks(ax)
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right", fontsize=8)
    for ax in axes[count:]:
        ax.set_visible(False)
    suptitle = figure.suptitle(
        f"Planning: power of Welch's two-sided t-test on R_T at α = {analysis.alpha:g} "
        f"({analysis.draws} simulated studies per size)",
        fontsize=11,
    )
    return fit_titles(figure, suptitle)
