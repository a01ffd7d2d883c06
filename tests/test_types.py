"""The type checker runs with the suite: no new mypy error anywhere, none at all in sim,
learner and the core (tests/mypy_baseline.py)."""

from __future__ import annotations

import tomllib
import warnings
from collections import Counter

from tests import mypy_baseline


def test_no_type_error_beyond_the_baseline() -> None:
    errors, output = mypy_baseline.run_mypy()
    baseline = mypy_baseline.read_baseline()
    assert not mypy_baseline.problems(errors, baseline), output
    if sum(errors.values()) < sum(baseline.values()):
        warnings.warn(
            "fewer mypy errors than mypy-baseline.txt: `python -m tests.mypy_baseline --update`",
            stacklevel=1,
        )


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
