"""The type checker's rule (tests/mypy_baseline.py, run by `make lint`): no new mypy error
anywhere, none at all in sim, learner and the core."""

from __future__ import annotations

import tomllib
from collections import Counter

from tests import mypy_baseline


def test_mypy_reports_a_type_ignore_that_is_no_longer_needed() -> None:
    config = tomllib.loads((mypy_baseline.ROOT / "pyproject.toml").read_text())["tool"]["mypy"]
    assert config["warn_unused_ignores"] is True
    assert {"sim", "learner", "study"} <= set(config["files"])


def test_the_rule_catches_new_errors() -> None:
    """An error in the core, or one more than a file's baseline, is refused."""
    baseline = Counter({"server/main.py": 1})
    assert mypy_baseline.problems(Counter({"server/main.py": 1}), baseline) == []
    assert mypy_baseline.problems(Counter({"server/main.py": 2}), baseline)
    assert mypy_baseline.problems(Counter({"study/services/sessions.py": 1}), baseline)
    assert mypy_baseline.problems(Counter({"study/settings.py": 1}), baseline)
    assert mypy_baseline.problems(Counter({"learner/run.py": 1}), baseline)
