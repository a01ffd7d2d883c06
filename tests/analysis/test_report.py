"""write_report: the files a researcher opens, and that their tables match the input."""

from __future__ import annotations

import html
import re
import unicodedata
import zlib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from fontTools.agl import toUnicode
from PIL import Image

from analysis import EpisodeTableError, ReportResult, write_report
from analysis import markdown as md
from analysis.__main__ import main
from analysis.formats import FIGURE_FORMATS_VARIABLE
from analysis.power import normal_sample_size
from analysis.report import FIGURE_FILES, TABLE_FILES
from tests.analysis.helpers import HAND_CASE, episodes_from_curves

N_EPISODES = 12


def study_episodes() -> pd.DataFrame:
    """3 autonomous, 3 agent-advised and 6 human-advised agents whose advised runs learn faster."""
    rng = np.random.default_rng(11)
    episode = np.arange(N_EPISODES)
    curves, epsilon = {}, {}
    for method, count, start in (("autonomous", 3, 8.0), ("agent", 3, 3.0), ("human", 6, 4.0)):
        for i in range(1, count + 1):
            learned = 1 / (1 + np.exp(-(episode - start - rng.uniform(-1, 1))))
            label = f"{method}-{i}"
            curves[label] = (method, -1.0 + 4.0 * learned + rng.normal(0, 0.3, N_EPISODES))
            epsilon[label] = np.maximum(0.01, 0.6 ** (episode + 1))
    table = episodes_from_curves(curves, epsilon=epsilon)
    table["seed"] = table["session_id"] * 10
    return table


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> tuple[pd.DataFrame, ReportResult]:
    """The report as a researcher gets it: every figure in every format (the environment
    of the tests asks for PNGs alone, tests/conftest.py)."""
    episodes = study_episodes()
    out = tmp_path_factory.mktemp("report") / "nested" / "study-1"
    with pytest.MonkeyPatch.context() as patch:
        patch.delenv(FIGURE_FORMATS_VARIABLE, raising=False)
        written = write_report(
            episodes, out, title="Pilot study", notes=["command: ideeprl batch --demo"]
        )
    return episodes, written


@pytest.mark.slow
def test_every_file_is_written_and_listed(report: tuple[pd.DataFrame, ReportResult]) -> None:
    _, result = report
    assert result.report == result.out_dir / "report.md"
    assert set(result.figures) == set(FIGURE_FILES)
    assert set(result.tables) == {*TABLE_FILES, "comparisons", "power"}  # against a baseline
    assert sorted(p.name for p in result.out_dir.iterdir()) == sorted(p.name for p in result.files)
    assert result.formats == ("png", "svg", "pdf")
    for path in result.figures.values():
        with Image.open(path) as image:
            assert image.format == "PNG" and min(image.size) > 300
            size = (image.size[0] / DPI * 72, image.size[1] / DPI * 72)  # in points
        svg = path.with_suffix(".svg").read_text()
        pdf = path.with_suffix(".pdf").read_bytes()
        assert svg.lstrip().startswith("<?xml") and pdf.startswith(b"%PDF")
        # the same figure: the same page, and the same words on it
        assert svg_size(svg) == pytest.approx(size) and pdf_size(pdf) == pytest.approx(size)
        words = svg_words(svg)
        assert words and words == pdf_words(pdf), path.name


DPI = 150
"""`save_figure`'s resolution: a PNG's pixels per inch of the figure (72 points)."""


def svg_size(svg: str) -> tuple[float, float]:
    found = re.search(r'<svg [^>]*width="([\d.]+)pt" height="([\d.]+)pt"', svg)
    assert found, svg[:400]
    return float(found[1]), float(found[2])


def pdf_size(pdf: bytes) -> tuple[float, float]:
    found = re.search(rb"/MediaBox \[ *0 0 ([\d.]+) ([\d.]+) *\]", pdf)
    assert found, pdf[:400]
    return float(found[1]), float(found[2])


def svg_words(svg: str) -> set[str]:
    """The words (of three letters or more) of a figure's texts in its SVG: matplotlib
    draws each text as paths, under a comment holding the text."""
    texts = re.findall(r"<!-- (.*?) -->", svg, re.S)
    return {w for text in texts for w in re.findall(r"[A-Za-z]{3,}", html.unescape(text))}


PDF_STRING = rb"\((?:[^()\\]|\\.)*\)"
"""A PDF string, (text), its parentheses and backslashes escaped by a backslash."""


def pdf_words(pdf: bytes) -> set[str]:
    """The words of a figure's texts in its PDF: the strings each text object (BT ... ET)
    shows, each byte read through its font's encoding (matplotlib's fonts name each glyph
    they hold, a ligature such as "ff" one of its own) and the text's pieces joined."""
    objects = dict(re.findall(rb"(\d+) 0 obj(.*?)endobj", pdf, re.S))
    fonts: dict[bytes, dict[int, str]] = {}
    for name, number in re.findall(rb"/(F\d+) (\d+) 0 R", pdf):
        listed = re.search(rb"/Differences \[(.*?)\]", objects[number], re.S)
        assert listed, objects[number][:400]
        glyphs, code = {}, 0
        for token in listed[1].split():
            if token.isdigit():
                code = int(token)
            else:
                glyphs[code], code = toUnicode(token[1:].decode()), code + 1
        fonts[name] = glyphs
    words: set[str] = set()
    for stream in re.findall(rb"stream\r?\n(.*?)\r?\nendstream", pdf, re.S):
        try:
            content = zlib.decompress(stream)
        except zlib.error:
            continue
        for shown in re.findall(rb"\bBT\b(.*?)\bET\b", content, re.S):
            glyphs, text = {}, ""
            for font, string in re.findall(rb"/(F\d+) [\d.]+ Tf|(" + PDF_STRING + rb")", shown):
                if font:
                    glyphs = fonts[font]
                else:
                    raw = re.sub(rb"\\(.)", rb"\1", string[1:-1], flags=re.S)
                    text += "".join(glyphs.get(byte, " ") for byte in raw)
            words |= set(re.findall(r"[A-Za-z]{3,}", unicodedata.normalize("NFKC", text)))
    return words


@pytest.mark.slow
def test_the_csv_tables_match_the_input(report: tuple[pd.DataFrame, ReportResult]) -> None:
    episodes, result = report
    agents = pd.read_csv(result.tables["agents"]).set_index("label")
    by_hand = episodes.groupby("label")["collected_reward"].sum()
    assert agents["R_T"].to_dict() == pytest.approx(by_hand.to_dict())
    assert agents["seed"].to_dict() == episodes.groupby("label")["seed"].first().to_dict()

    methods = pd.read_csv(result.tables["methods"]).set_index("method")
    curve = episodes.groupby(["method", "episode"])["collected_reward"].mean()
    for method in ("autonomous", "agent", "human"):
        assert methods.loc[method, "R_T"] == pytest.approx(curve.loc[method].sum())
    base = curve.loc["autonomous"].sum()
    assert methods.loc["agent", "improvement_pct"] == pytest.approx(
        (curve.loc["agent"].sum() - base) / base * 100
    )

    tests = pd.read_csv(result.tables["t_tests"])
    row = tests[(tests.method_a == "human") & (tests["sample"] == "agent_totals")].iloc[0]
    assert (row["method_b"], row["n_a"], row["n_b"]) == ("autonomous", 6, 3)
    assert set(tests.loc[tests["sample"] == "episode_means", "n_a"]) == {N_EPISODES}

    correlation = pd.read_csv(result.tables["correlation"], index_col="label")
    wide = episodes.pivot(index="episode", columns="label", values="collected_reward")
    expected = np.corrcoef(wide[correlation.columns].to_numpy().T)
    assert np.allclose(correlation.to_numpy(), expected)

    curves = pd.read_csv(result.tables["curves"]).set_index(["method", "episode"])
    assert curves["mean"].to_dict() == pytest.approx(curve.to_dict())


def test_the_markdown_shows_the_files_and_numbers_in_plain_words(
    report: tuple[pd.DataFrame, ReportResult],
) -> None:
    _, result = report
    text = result.report.read_text(encoding="utf-8")
    assert text.startswith("# Pilot study\n\n- command: ideeprl batch --demo\n")
    links = re.findall(r"\]\(([^)]+)\)", text)
    assert set(FIGURE_FILES.values()) | set(TABLE_FILES.values()) <= set(links)
    assert all((result.out_dir / link).is_file() for link in links)  # relative, and there
    methods = pd.read_csv(result.tables["methods"]).set_index("method")
    agent = methods.loc["agent"]
    assert (
        f"- **agent-IDeepRL** (3 agents × {N_EPISODES} episodes): R_T = {agent['R_T']:.2f}" in text
    )
    assert f"{agent['improvement_pct']:+.2f} %" in text
    assert "the paper's Table 2" in text and "598 degrees of freedom" in text
    assert "| R_T autonomous DeepRL | 369.88 |" in text
    assert "| \\|t\\| autonomous DeepRL vs agent-IDeepRL | 7.6829 |" in text
    assert "| p autonomous DeepRL vs agent-IDeepRL | 6.3947e-14 |" in text
    assert f"these runs have {N_EPISODES} episodes per agent" in text
    assert "Figure 6 draws 3 of the 6 human-IDeepRL agents" in text
    assert "Mean epsilon reaches 1 %: autonomous DeepRL at episode 10" in text


def test_the_power_section_plans_from_the_agents_r_t(
    report: tuple[pd.DataFrame, ReportResult],
) -> None:
    """Each method against the baseline, both targets, by simulation and closed form,
    labelled as planning; the numbers are those of the power table and the library."""
    episodes, result = report
    text = result.report.read_text(encoding="utf-8")
    section = text.split("## Power: ")[1].split("\n## ")[0]
    assert section.startswith("how many participants a study needs (planning, not a test)")
    assert "not a test of this one" in section and "2000 studies per size (seed 0)" in section
    table = pd.read_csv(result.tables["power"])
    assert list(zip(table.method, table.power, strict=True)) == [
        ("agent", 0.8), ("agent", 0.9), ("human", 0.8), ("human", 0.9)
    ]  # fmt: skip
    r_t = episodes.groupby("label")["collected_reward"].sum()
    agent = r_t[[f"agent-{i}" for i in (1, 2, 3)]].to_numpy()
    base = r_t[[f"autonomous-{i}" for i in (1, 2, 3)]].to_numpy()
    row = table.iloc[0]
    assert row["effect"] == pytest.approx(agent.mean() - base.mean())
    assert (row["sd"], row["baseline_sd"]) == pytest.approx((agent.std(ddof=1), base.std(ddof=1)))
    assert row["n_closed_form"] == normal_sample_size(
        row["effect"], row["sd"], row["baseline_sd"], 0.8, 0.05
    )
    assert (
        f"| agent-IDeepRL vs autonomous DeepRL | {row['effect']:+.2f} (d = {row['d']:.2f}) | "
        f"{row['sd']:.2f} / {row['baseline_sd']:.2f} | 3 + 3 | 80 % | {row['n_bootstrap']} | "
        f"{row['n_fitted']} | {row['n_closed_form']} |"
    ) in section
    assert "(power.png)" in section and "(power.svg)" in section


@pytest.mark.slow
def test_a_report_in_fewer_formats_lists_and_links_those_and_keeps_no_earlier_ones(
    tmp_path: Path,
) -> None:
    """The tests' environment asks for PNGs alone (tests/conftest.py): a report written so
    into a folder that holds one in every format leaves none of the earlier SVG and PDF
    files, lists only what it wrote and links only that."""
    episodes = episodes_from_curves(HAND_CASE)
    out = tmp_path / "report"
    every = write_report(episodes, out, formats="png,svg,pdf")
    assert {p.suffix for p in every.files} == {".md", ".png", ".svg", ".pdf", ".csv"}
    assert "(power.svg)" in every.report.read_text(encoding="utf-8")
    fewer = write_report(episodes, out)
    assert fewer.formats == ("png",) and fewer.vector_figures == []
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in fewer.files)
    text = fewer.report.read_text(encoding="utf-8")
    assert "(power.png)" in text and ".svg" not in text and ".pdf" not in text
    assert all((out / link).is_file() for link in re.findall(r"\]\(([^)]+)\)", text))


@pytest.mark.slow
def test_too_few_agents_leave_the_power_section_with_the_reason(tmp_path: Path) -> None:
    result = write_report(episodes_from_curves(HAND_CASE), tmp_path / "hand")
    section = result.report.read_text(encoding="utf-8").split("## Power: ")[1].split("\n## ")[0]
    assert "Left out: human has 1 agent(s); power needs at least 2 per arm" in section
    assert "| agent-IDeepRL vs autonomous DeepRL |" in section
    assert "| human-IDeepRL vs autonomous DeepRL |" not in section
    assert set(pd.read_csv(result.tables["power"]).method) == {"agent"}
    alone = write_report(episodes_from_curves(HAND_CASE), tmp_path / "none", baseline=None)
    assert "Left out: power compares each method with a baseline" in alone.report.read_text()
    assert "power" not in alone.figures and "power" not in alone.tables


@pytest.mark.slow
def test_the_paper_comparison_needs_the_papers_methods(tmp_path: Path) -> None:
    curves = {"o1": ("oracle", [1.0, 2.0, 3.0]), "r1": ("random", [0.0, 1.0, 0.0])}
    result = write_report(episodes_from_curves(curves), tmp_path, baseline="random")
    text = result.report.read_text(encoding="utf-8")
    assert "None of the paper's methods" in text and "369.88" not in text
    assert pd.read_csv(result.tables["paper"]).empty
    # no human sessions: Figure 6 shows the first advised method against the baseline
    assert "Figure 6 shows the individual oracle-IDeepRL agents" in text
    assert "Figure 6's reference is r1" in text


@pytest.mark.slow
def test_a_single_method_still_gets_a_report_without_figure_6(tmp_path: Path) -> None:
    table = episodes_from_curves({"a": ("autonomous", [1.0, 2.0]), "b": ("autonomous", [2.0, 2.0])})
    result = write_report(table, tmp_path)
    assert "individual_agents" not in result.figures
    assert "Figure 6 is left out" in result.report.read_text(encoding="utf-8")
    assert result.notes[0].startswith("Figure 6 is left out")


def test_a_single_method_says_why_it_has_no_comparison_table(tmp_path: Path) -> None:
    """A table of tests or differences with no row would be a header alone: the report
    says there is no pair to compare instead."""
    table = episodes_from_curves({"a": ("autonomous", [1.0, 2.0]), "b": ("autonomous", [2.0, 2.0])})
    text = write_report(table, tmp_path).report.read_text(encoding="utf-8")
    assert "No pair of methods to compare: the report has one method." in text
    lines = text.splitlines()
    for i, line in enumerate(lines[:-1]):
        if line.startswith("|---") or line.startswith("|--"):
            assert lines[i + 1].startswith("|"), f"a table with no rows: {lines[i - 1]}"


@pytest.mark.slow
def test_one_agent_and_one_method_are_counted_in_the_singular(tmp_path: Path) -> None:
    text = write_report(episodes_from_curves(HAND_CASE), tmp_path / "hand").report.read_text()
    assert "- **human-IDeepRL** (1 agent × 3 episodes)" in text, text
    one = {"a": ("autonomous", [1.0, 2.0])}
    text = write_report(episodes_from_curves(one), tmp_path / "one").report.read_text()
    assert "1 agent in 1 method, 2 episodes each." in text, text
    assert "1 agents" not in text and "1 methods" not in text


@pytest.mark.slow
def test_the_summary_reads_advice_against_its_control_by_the_primary_test(
    tmp_path: Path,
) -> None:
    """The comparison that isolates the advice (advised method against its procedure
    control) is one of the plan's comparisons: the summary quotes its primary test, not the
    pooled t-test of the paper's table."""
    rng = np.random.default_rng(4)
    curves = {}
    for method, shift, spread in (("autonomous", 0.0, 0.2), ("agent", 1.0, 2.0),
                                  ("procedure", 0.3, 0.2)):  # fmt: skip
        for i in range(1, 5):
            curves[f"{method}-{i}"] = (method, shift + rng.normal(0, spread, 6))
    table = episodes_from_curves(curves)
    table["seed"] = table["label"].str[-1].astype(int)
    result = write_report(table, tmp_path, primary="paired", power_draws=200)
    comparisons = pd.read_csv(result.tables["comparisons"])
    control = comparisons[comparisons["baseline"].eq("procedure")].iloc[0]
    assert control["method"] == "agent" and control["primary"] == "paired"
    text = result.report.read_text()
    (line,) = [x for x in text.splitlines() if x.startswith("- agent-IDeepRL vs procedure")]
    primary = f"t = {control['primary_statistic']:.2f}, p = {md.p_value(control['primary_p'])}"
    assert f"Primary test (paired t-test over seeds of the agents' R_T): {primary}" in line
    pooled = result.analysis.t_tests.set_index(["method_a", "method_b", "sample"])
    student = pooled.loc[("agent", "procedure", "agent_totals"), "t"]
    assert f"t = {student:.2f}," not in line, "the pooled test is not the plan's"


def test_no_percentage_against_a_negative_reference(tmp_path: Path) -> None:
    """A short run's negative baseline: the differences are in points, never "+405 %"."""
    curves = {
        "a1": ("autonomous", [-2.0, -1.0]),
        "a2": ("autonomous", [-3.0, -2.0]),
        "h1": ("human", [1.0, 2.0]),
        "h2": ("human", [0.0, 2.0]),
    }
    text = write_report(episodes_from_curves(curves), tmp_path).report.read_text()
    # autonomous R_T -4, human 2.5: 6.5 points more (as a percentage of |-4|: +162.50 %)
    assert "it collects +6.50 points (more reward) compared with autonomous DeepRL" in text
    assert "| +6.50 points |" in text, "the methods table"
    assert "| h1 | human-IDeepRL | 3.00 | +7.00 points |" in text, "the agents table"
    assert not re.search(r"[+-]\d+\.\d+ %", text), re.findall(r"[+-]\d+\.\d+ %", text)


def test_bad_input_writes_nothing(tmp_path: Path) -> None:
    out = tmp_path / "report"
    table = episodes_from_curves(HAND_CASE)
    with pytest.raises(EpisodeTableError, match="unequal numbers of episodes"):
        write_report(table[~((table.session_id == 1) & (table.episode == 3))], out)
    with pytest.raises(EpisodeTableError, match="no agent labelled 'DeepRL9' for Figure 6"):
        write_report(table, out, reference_label="DeepRL9")
    with pytest.raises(EpisodeTableError, match="baseline method 'autonomus' has no sessions"):
        write_report(table, out, baseline="autonomus")
    assert not out.exists()


@pytest.mark.slow
def test_the_command_line_writes_a_report_from_a_csv(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    csv = tmp_path / "episodes.csv"
    episodes_from_curves(HAND_CASE).to_csv(csv, index=False)
    assert main([str(csv), str(tmp_path / "out"), "--title", "From CSV"]) == 0
    printed = capsys.readouterr().out.split()
    assert str(tmp_path / "out" / "report.md") == printed[0]
    assert (tmp_path / "out" / "report.md").read_text(encoding="utf-8").startswith("# From CSV")
    broken = tmp_path / "broken.csv"
    episodes_from_curves(HAND_CASE).drop(columns=["episode"]).to_csv(broken, index=False)
    assert main([str(broken), str(tmp_path / "none")]) == 2
    assert "lacks column(s) episode" in capsys.readouterr().err
    assert not (tmp_path / "none").exists()


@pytest.mark.slow
def test_a_new_report_leaves_none_of_an_earlier_ones_files(tmp_path: Path) -> None:
    """A report of two methods writes Figure 6; one of a single method into the same folder
    has none: the earlier figure must not stay beside it, read as this report's. Files
    that are not a report's stay."""
    two = {"a": ("autonomous", [1.0, 2.0]), "b": ("human", [2.0, 2.0])}
    first = write_report(episodes_from_curves(two), tmp_path)
    assert "individual_agents" in first.figures
    (tmp_path / "notes.txt").write_text("mine")
    one = {"a": ("autonomous", [1.0, 2.0]), "b": ("autonomous", [2.0, 2.0])}
    write_report(episodes_from_curves(one), tmp_path)
    assert not (tmp_path / FIGURE_FILES["individual_agents"]).exists()
    assert (tmp_path / "notes.txt").read_text() == "mine"


@pytest.mark.slow
def test_a_run_shorter_than_the_band_window_still_gets_a_band_figure(tmp_path: Path) -> None:
    """3 episodes under the 10-episode moving average drew an empty figure that the report
    embedded; the window now shrinks to the run (here: none) and the text says so."""
    result = write_report(episodes_from_curves(HAND_CASE), tmp_path)
    text = result.report.read_text(encoding="utf-8")
    assert "confidence_bands" in result.figures
    assert f"]({FIGURE_FILES['confidence_bands']})" in text
    assert "no moving average: the run is too short for one" in text
    assert "moving average over 10 episodes" not in text


@pytest.mark.slow
def test_a_one_episode_run_leaves_the_band_figure_out_with_the_reason(tmp_path: Path) -> None:
    table = episodes_from_curves({"a": ("autonomous", [1.0]), "b": ("agent", [2.0])})
    result = write_report(table, tmp_path)
    text = result.report.read_text(encoding="utf-8")
    assert "confidence_bands" not in result.figures
    assert not (tmp_path / FIGURE_FILES["confidence_bands"]).exists()
    assert FIGURE_FILES["confidence_bands"] not in text
    assert "The bootstrap-band figure is left out: the run has 1 episode" in text
    assert any(n.startswith("The bootstrap-band figure is left out") for n in result.notes)
