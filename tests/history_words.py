"""Comments and docstrings that narrate the code's history instead of saying what it is and
why: what it used to do, which issue or development session changed it, when. That belongs
in the commit message, where `git log` keeps it beside the change (`../shared/STYLE.md`: "comments
speak of the code as it is"). `python -m tests.history_words` lists them;
tests/test_history_words.py keeps the list empty.

Only words are matched, so a few phrases whose sense here is not history are left out
(`EXCLUDED`, each with its reason). Documenting an old data format the code still reads
("rows stored before 0010 hold NULL") is what the code does now, and is not matched."""

from __future__ import annotations

import ast
import io
import re
import sys
import tokenize
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).absolute().parents[1]
PACKAGES = ("sim", "tasks", "learner", "study", "runs", "server", "analysis", "cli")

HISTORY = re.compile(
    "|".join(
        phrase.replace(" ", r"\s+")
        for phrase in (
            r"\bused to\b",
            r"\bno longer\b",
            r"\bany\s*more\b",
            r"\bpreviously\b",
            r"\bformerly\b",
            r"\buntil now\b",
            r"\bas before\b",
            r"\bearlier versions?\b",
            r"\bold (code|version|behaviou?r|implementation)\b",
            r"\bbefore this (change|commit|fix|issue|patch|rewrite|refactor)",
            r"\b(was|were|has been|have been) (changed|replaced|renamed|removed|rewritten)\b",
            r"\b(is|are|does|do|has|have) now\b",
            r"\bissues? #?\d+",
            r"#\d{2,}\b",
            r"\b(earlier|previous|last|past|former|development|dev) sessions?\b",
            r"\b(this|that) session('s)? (review|work|change|fix)",
            r"\b(fixed|fixes|fixing) (a |the |an )?(bug|crash|regression|problem|issue)",
            r"\b(bug\s*fix|fixed (in|by))\b",
            r"\ba new user's\b",
            r"\bcommit [0-9a-f]{7,40}\b",
            r"\b20\d\d-[01]\d-[0-3]\d\b",
        )
    ),
    re.IGNORECASE,
)
"""Phrases that narrate history: what the code was, what changed it, when."""

EXCLUDED: dict[str, str] = {
    r"\brate used to choose\b": "passive: the rate with which the action was chosen",
    r"\bno longer (exists?|runs?|has|needed|this worker's)\b": (
        "a session, worker, design or dependency that changed while the program runs"
    ),
    r"\b(nobody|no one|no \w+)\b[^.;:]*?\bany\s*more\b": (
        "a participant or process that has gone while the program runs"
    ),
    r"\bwhere\b[^.;:]*? (is|are) now\b": "where a thing is at this moment",
    r"\bcan no longer read\b": "a stored run that today's code cannot read",
    r"\bkeep until now\b": "until this point of a save, not of the code's history",
    r"\blooks like, and no longer\b": "no longer than that (a length)",
    r"\bpreviously trained\b": "an advisor trained before the run it advises (agent-IDeepRL)",
    r"IthanMoreira/DeppRL, commit [0-9a-f]{7,40}": "the authors' public code, cited",
    r"Create Date: \d": "Alembic's revision header",
    r"[-/_]20\d\d-[01]\d-[0-3]\d": "a file's name (a benchmark log, a results folder), cited",
    r"\b20\d\d-[01]\d-[0-3]\dT": "an example of a timestamp's format",
}
"""Phrase (a regex) -> why its sense here is not history. A match inside one is skipped."""


class Hit(NamedTuple):
    path: str
    line: int
    text: str

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: {self.text}"


def prose(source: str) -> Iterator[tuple[int, str]]:
    """Each comment, and each docstring (a string statement: a module's, a class's, a
    function's or an attribute's), with the line it starts on."""
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            yield token.start[0], token.string
    for node in ast.walk(ast.parse(source)):
        if (
            isinstance(node, ast.Expr)
            and isinstance(node.value, ast.Constant)
            and isinstance(node.value.value, str)
        ):
            yield node.lineno, node.value.value


def narrated(text: str) -> Iterator[tuple[int, str]]:
    """Where `text` narrates history: (line offset in it, that line), once a line. A phrase
    may run over a line's end, as a docstring's sentences do."""
    exclusions = [
        m.span()
        for phrase in EXCLUDED
        for m in re.finditer(phrase.replace(" ", r"\s+"), text, re.IGNORECASE)
    ]
    lines = text.split("\n")
    seen: set[int] = set()
    for match in HISTORY.finditer(text):
        if any(start < match.end() and match.start() < end for start, end in exclusions):
            continue
        offset = text.count("\n", 0, match.start())
        if offset not in seen:
            seen.add(offset)
            yield offset, lines[offset].strip()


def hits(files: Iterable[Path], root: Path = ROOT) -> list[Hit]:
    found = [
        Hit(str(path.relative_to(root)), start + offset, line)
        for path in files
        for start, text in prose(path.read_text())
        for offset, line in narrated(text)
    ]
    return sorted(found)


def package_files(root: Path = ROOT) -> list[Path]:
    return sorted(p for package in PACKAGES for p in (root / package).rglob("*.py"))


def main() -> int:
    found = hits(package_files())
    for hit in found:
        print(hit)
    print(f"{len(found)} comment or docstring lines narrate history", file=sys.stderr)
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
