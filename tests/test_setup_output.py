"""`make serve` on a fresh clone says only what a researcher needs: the editable install
it runs (`make setup`) prints no setuptools notice. The install's command is read from the
Makefile (`make -n`) and its build hook run, in that command's environment, over a copy of
the sources (this checkout's venv is left alone)."""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.test_install import _top_level

ROOT = Path(__file__).absolute().parents[1]


def _install_environment() -> dict[str, str]:
    """The variables the Makefile sets on its editable install's command line."""
    if shutil.which("make") is None:
        pytest.skip("make not found")
    planned = subprocess.run(
        ["make", "-n", "-B", ".venv/.installed"], cwd=ROOT, capture_output=True, text=True
    ).stdout
    [line] = [line for line in planned.splitlines() if "pip install" in line and " -e " in line]
    words = shlex.split(line)
    assignments = words[: next(i for i, w in enumerate(words) if "=" not in w)]
    return dict(word.split("=", 1) for word in assignments)


def test_the_editable_install_prints_no_setuptools_notice(tmp_path: Path) -> None:
    source = tmp_path / "source"
    source.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, source / name)
    for name in _top_level():
        shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__"))
    hook = f"from setuptools import build_meta; build_meta.build_editable({str(tmp_path)!r})"
    env = {**os.environ, **_install_environment()}
    built = subprocess.run(
        [sys.executable, "-c", hook], cwd=source, env=env, capture_output=True, text=True
    )
    assert built.returncode == 0, built.stderr[-2000:]
    assert "Editable installation" not in built.stdout + built.stderr, built.stderr[-2000:]
