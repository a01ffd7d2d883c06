"""What `pip install ideeprl` brings is what the programs import: test-only packages are
in the `dev` extra, and an extra whose API we reach into has an upper bound we tested. (The
import contracts in pyproject.toml are checked by `make lint`.)"""

from __future__ import annotations

import ast
import tomllib
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement

ROOT = Path(__file__).absolute().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
PROJECT = PYPROJECT["project"]
PACKAGES = ("sim", "tasks", "learner", "study", "runs", "server", "analysis", "cli")


def _requirements(names: list[str]) -> dict[str, Requirement]:
    found = (Requirement(n) for n in names)
    return {r.name.lower().replace("_", "-"): r for r in found}


def _imported(package: str) -> set[str]:
    """Top-level modules imported anywhere in a package's code."""
    names: set[str] = set()
    for path in (ROOT / package).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                names.add(node.module.split(".")[0])
    return names


def test_frictionless_is_for_the_tests_only() -> None:
    assert "frictionless" not in _requirements(PROJECT["dependencies"])
    assert "frictionless" in _requirements(PROJECT["optional-dependencies"]["dev"])
    for package in PACKAGES:
        assert "frictionless" not in _imported(package), package


def test_the_sb3_baseline_is_bounded_to_the_versions_it_was_tested_with() -> None:
    """learner/sb3_dqn.py calls SB3's private rollout members, which a minor release may
    change: the extra has an upper bound, and the installed SB3 (the tested one) is in it."""
    [sb3] = _requirements(PROJECT["optional-dependencies"]["sb3"]).values()
    assert any(spec.operator in ("<", "<=", "~=", "==") for spec in sb3.specifier), sb3
    try:
        installed = metadata.version("stable-baselines3")
    except metadata.PackageNotFoundError:
        pytest.skip("stable-baselines3 is not installed here")
    assert sb3.specifier.contains(installed), (str(sb3), installed)
