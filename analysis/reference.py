"""The authors' published curves as a reference for Figure 5 (`ideeprl report --reference
authors`); data and provenance in `analysis/data/`."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
from matplotlib.figure import Figure

from analysis.episodes import method_name
from analysis.figures import method_color
from analysis.paper import PAPER_R_T

REFERENCES = ("authors",)
AUTHORS_CURVES = Path(__file__).parent / "data" / "authors_mean_curves.csv"
AUTHORS_METHODS = ("autonomous", "agent")
"""The methods the authors' curves exist for (`<method>_mean_reward` columns)."""
AUTHORS_SCHEMES = {"autonomous": "authors-autonomous", "agent": "authors-interactive"}
"""The reward scheme each curve was scored under (the scripts that logged it)."""


def authors_curves() -> pd.DataFrame:
    """episode, method, mean, sd: the authors' mean reward per episode (300 each)."""
    raw = pd.read_csv(AUTHORS_CURVES)
    frames = [
        pd.DataFrame(
            {
                "episode": raw["episode"],
                "method": method,
                "mean": raw[f"{method}_mean_reward"],
                "sd": raw[f"{method}_sd"],
            }
        )
        for method in AUTHORS_METHODS
    ]
    return pd.concat(frames, ignore_index=True)


def overlay_authors(figure: Figure, methods: list[str], n_episodes: int) -> None:
    """Draw the authors' mean curves (dashed, each in its method's colour) on Figure 5."""
    ax = figure.axes[0]
    curves = authors_curves()
    for method in AUTHORS_METHODS:
        rows = curves[(curves["method"] == method) & (curves["episode"] <= n_episodes)]
        color = method_color(method, methods) if method in methods else "0.4"
        ax.plot(
            rows["episode"], rows["mean"], color=color, lw=1.0, ls="--", alpha=0.9,
            label=f"{method_name(method)}, the authors' mean ({AUTHORS_SCHEMES[method]})",
        )  # fmt: skip
    ax.legend(loc="lower right", fontsize="small")


def authors_totals(n_episodes: int) -> pd.DataFrame:
    """method, scheme, R_T of the authors' curves over the first `n_episodes`, and the
    paper's printed R_T (over 300 episodes)."""
    curves = authors_curves()
    rows = []
    for method in AUTHORS_METHODS:
        values = curves[(curves["method"] == method) & (curves["episode"] <= n_episodes)]
        rows.append(
            {
                "method": method,
                "name": method_name(method),
                "scheme": AUTHORS_SCHEMES[method],
                "episodes": len(values),
                "authors_curve_R_T": float(values["mean"].sum()),
                "paper_R_T": PAPER_R_T[method],
            }
        )
    return pd.DataFrame(rows)
