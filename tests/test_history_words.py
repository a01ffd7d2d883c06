"""Comments and docstrings say what the code is and why; its history is in `git log`
(tests/history_words.py)."""

from __future__ import annotations

from pathlib import Path

from tests import history_words

PENDING: set[tuple[str, str]] = set()
"""Hits in files that another change is rewriting at the same time (path, words of the
line): they go with that change, and then from here."""


def pending(hit: history_words.Hit) -> bool:
    return any(hit.path == path and words in hit.text for path, words in PENDING)


def test_no_comment_or_docstring_narrates_history() -> None:
    found = [h for h in history_words.hits(history_words.package_files()) if not pending(h)]
    assert found == [], "say what the code is and why; history goes to the commit message:\n" + (
        "\n".join(map(str, found))
    )


def test_a_docstring_that_narrates_history_is_found(tmp_path: Path) -> None:
    module = tmp_path / "module.py"
    module.write_text(
        '"""The replay memory."""\n\n'
        "def save():\n"
        '    """Write the filled frames; this used to write the whole\n'
        '    capacity (issue 12)."""\n'
        "    # fixed a crash when empty\n"
    )
    found = history_words.hits([module], root=tmp_path)
    assert [(hit.path, hit.line) for hit in found] == [
        ("module.py", 4),
        ("module.py", 5),
        ("module.py", 6),
    ]


def test_the_same_words_in_another_sense_are_not_history(tmp_path: Path) -> None:
    module = tmp_path / "module.py"
    module.write_text(
        '"""A previously trained advisor; rows stored before 0010 hold NULL."""\n\n'
        "EPSILON = 0.1\n"
        '"""Exploration rate used to choose this step\'s action."""\n'
        "# the session no longer exists: nobody is listening any more\n"
    )
    assert history_words.hits([module], root=tmp_path) == []
