"""Where a run was computed: the code that decides it, the machine, the numerics.

A study compares numbers made by runs; two runs compare only if the same code computed
them the same way. `record(spec)` is what a worker stores with its session each time the
run starts or resumes (`sessions.provenance`), and the report's audit compares:

- `code`: a content hash of every Python file under `sim/` and `learner/` (the files that
  decide a run's course), the same in a git checkout, a copy or an installed package, and
  different as soon as one of those files changes;
- `commit`: the git commit when the code runs from a checkout (None otherwise);
- `cpu`: the CPU kind (`learner.machine.cpu_kind`), `torch` and `python` versions;
- `numerics`: the run's pinned device, precision, compiled convolutions (variant and
  layers) and threads.

Torch-free (its version is read from the installed package's metadata).
"""

from __future__ import annotations

import hashlib
import platform
import subprocess
from functools import cache
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

from learner import machine

if TYPE_CHECKING:
    from learner.config import ConvKernel, DQNConfig, Precision

PACKAGES = ("sim", "learner")
"""The packages whose files decide a run's course."""
ROOT = Path(__file__).resolve().parents[1]
"""The folder holding them (a checkout's root, or site-packages)."""


def code_version(root: Path = ROOT) -> str:
    """`sha256:` and the first 16 hex digits of the hash of every `.py` file under `sim/`
    and `learner/` in `root`: their paths and contents, in a fixed order."""
    digest = hashlib.sha256()
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            if "__pycache__" in path.parts:
                continue
            digest.update(path.relative_to(root).as_posix().encode() + b"\0")
            digest.update(path.read_bytes() + b"\0")
    return "sha256:" + digest.hexdigest()[:16]


@cache
def _cached_code_version() -> str:
    return code_version()


def commit(root: Path = ROOT) -> str | None:
    """The git commit of the checkout the code runs from (with `+changes` when files differ
    from it), or None outside a checkout."""
    if not (root / ".git").exists():
        return None
    try:
        head = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True, text=True, timeout=5, check=True,
        ).stdout.strip()  # fmt: skip
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--", *PACKAGES],
            capture_output=True, text=True, timeout=5, check=True,
        ).stdout.strip()  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return None
    return head + ("+changes" if dirty else "")


def torch_version() -> str | None:
    try:
        return metadata.version("torch")
    except metadata.PackageNotFoundError:
        return None


class Numerics(TypedDict):
    device: str
    precision: Precision
    conv_kernel: ConvKernel
    torch_threads: int


class Provenance(TypedDict):
    """Where a run is computed (`sessions.provenance` keeps one per start, as-is, with the
    time and step it started at)."""

    code: str
    commit: str | None
    cpu: str
    torch: str | None
    python: str
    numerics: Numerics


def record(config: DQNConfig) -> Provenance:
    """What a worker stores when a run starts here (`config`: the run's pinned config)."""
    return Provenance(
        code=_cached_code_version(),
        commit=commit(),
        cpu=machine.cpu_kind(),
        torch=torch_version(),
        python=platform.python_version(),
        numerics=Numerics(
            device=config.device,
            precision=config.precision,
            conv_kernel=config.conv_kernel,
            torch_threads=config.torch_threads,
        ),
    )
