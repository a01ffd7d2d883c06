"""What the docs give a researcher to copy works as written: docs/api.md's "From Python"
snippet runs on a fresh SQLite file (all but its last line, which trains a paper-scale run
to the end; that call is checked against the worker's signature instead), and the example
design file makes its online study."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

from sqlalchemy import select

from study.db.engine import make_engine, make_session_factory
from study.db.models import Study, StudySession

DOCS = Path(__file__).resolve().parents[2] / "docs"
API_DOCS = DOCS / "api.md"
EXAMPLE_DESIGN = DOCS / "examples" / "online-study.yaml"


def _snippet() -> str:
    section = API_DOCS.read_text().split("## From Python", 1)[1]
    found = re.search(r"```python\n(.*?)```", section, re.DOTALL)
    assert found, "docs/api.md has a Python snippet under 'From Python'"
    return found.group(1)


def test_the_python_snippet_creates_its_study_and_session(tmp_path: Path) -> None:
    lines = _snippet().rstrip().splitlines()
    assert lines[-1].startswith("run_session("), lines[-1]
    url = f"sqlite:///{tmp_path / 'snippet.sqlite3'}"
    scope: dict[str, object] = {"url": url, "Path": Path}
    exec(compile("\n".join(lines[:-1]), str(API_DOCS), "exec"), scope)

    # Its last line binds to the worker's entry point as written.
    call = re.fullmatch(r"run_session\((.*)\)\s*(#.*)?", lines[-1])
    assert call, lines[-1]
    args = eval(f"(lambda *a, **k: (a, k))({call.group(1)})", scope)
    inspect.signature(scope["run_session"]).bind(*args[0], **args[1])  # type: ignore[arg-type]

    engine = make_engine(url)
    try:
        with make_session_factory(engine)() as db:
            (study,) = db.scalars(select(Study)).all()
            (session,) = db.scalars(select(StudySession)).all()
            assert study.name == "baselines" and session.study_id == study.id
            assert session.method == "autonomous" and session.seed == 3
    finally:
        engine.dispose()


def test_the_example_design_file_makes_its_online_study(tmp_path: Path) -> None:
    import yaml

    from cli.main import main

    written = yaml.safe_load(EXAMPLE_DESIGN.read_text())
    url = f"sqlite:///{tmp_path / 'example.sqlite3'}"  # this file, whatever DATABASE_URL says
    argv = ["study", "create", "--from", str(EXAMPLE_DESIGN), "--data-dir", str(tmp_path)]
    assert main([*argv, "--database-url", url]) == 0
    engine = make_engine(url)
    try:
        with make_session_factory(engine)() as db:
            (study,) = db.scalars(select(Study)).all()
            assert study.name == written["name"] and study.join_key
            design = study.design or {}
            assert design["conditions"].keys() == written["design"]["conditions"].keys()
            assert design["panel"]["codes"] == written["design"]["panel"]["codes"]
            assert design["alpha"] == written["design"]["alpha"]
    finally:
        engine.dispose()
