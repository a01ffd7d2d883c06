"""Where the request and response models live, and what crosses between the packages.

Every pydantic model is in `study/schemas/` (a route imports its bodies, never defines
them), and a function that one top-level package calls in another takes and returns typed
values, not `dict[str, Any]`. Both read the packages' source (no import: milliseconds)."""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

ROOT = Path(__file__).absolute().parents[1]
PACKAGES = ("sim", "learner", "study", "runs", "server", "analysis", "cli")
SCHEMAS = "study.schemas."
PYDANTIC_BASES = {"BaseModel", "BaseSettings", "RootModel"}

MODELS_ELSEWHERE = {
    "study.settings.Settings": "pydantic-settings reads the environment into a BaseSettings "
    "(a BaseModel): the configuration, not a body",
}
"""pydantic models allowed outside `study/schemas/`, with why."""


def _module_path(name: str) -> Path | None:
    base = ROOT / name.replace(".", "/")
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


@cache
def _trees() -> dict[str, ast.Module]:
    """Every module of the packages, by dotted name (alembic's scripts left out)."""
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            if "migrations" in parts:
                continue
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            found[name] = ast.parse(path.read_text(), str(path))
    return found


def _base_name(node: ast.expr) -> str:
    while isinstance(node, ast.Subscript):  # RootModel[list[int]]
        node = node.value
    return node.attr if isinstance(node, ast.Attribute) else getattr(node, "id", "")


def defined_models(trees: dict[str, ast.Module]) -> set[str]:
    """`module.Class` of every class whose bases lead to a pydantic model (by name)."""
    classes = {
        (module, node.name): {_base_name(b) for b in node.bases}
        for module, tree in trees.items()
        for node in tree.body
        if isinstance(node, ast.ClassDef)
    }
    models = set(PYDANTIC_BASES)
    while True:
        more = {name for (_, name), bases in classes.items() if bases & models} - models
        if not more:
            break
        models |= more
    return {f"{module}.{name}" for (module, name), bases in classes.items() if bases & models}


def test_every_pydantic_model_is_in_the_schemas_package() -> None:
    models = defined_models(_trees())
    assert "study.schemas.reports.ReportPublic" in models  # the walk finds models
    assert "study.schemas.sessions.SessionCreated" in models  # and their subclasses
    outside = {n for n in models if not n.startswith(SCHEMAS)} - set(MODELS_ELSEWHERE)
    assert not outside, f"move these to study/schemas/ (one module per topic): {sorted(outside)}"
    stale = set(MODELS_ELSEWHERE) - models
    assert not stale, f"gone: drop them from MODELS_ELSEWHERE: {sorted(stale)}"


def test_the_model_check_sees_a_model_in_a_route() -> None:
    route = ast.parse(
        "from pydantic import BaseModel\nfrom study.schemas.studies import StudyPublic\n"
        "class Body(BaseModel): pass\nclass More(StudyPublic): pass\nclass Plain: pass\n"
    )
    schemas = ast.parse("import pydantic\nclass StudyPublic(pydantic.BaseModel): pass\n")
    found = defined_models({"server.routes.x": route, "study.schemas.studies": schemas})
    assert found == {
        "server.routes.x.Body",
        "server.routes.x.More",
        "study.schemas.studies.StudyPublic",
    }
