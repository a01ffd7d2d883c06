"""The learner's config, records, advisors and strategies import without torch (the server
imports them at the top of its modules); the trainer brings torch when first asked for."""

import subprocess
import sys


def run(code: str) -> str:
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    return result.stdout.strip()


def test_light_names_import_without_torch() -> None:
    code = (
        "import sys, learner.config\n"
        "from learner import DQNConfig, make_advisor, make_strategy, StepRecord\n"
        "make_advisor('oracle', seed=1); make_strategy('early', 10)\n"
        "print('torch' in sys.modules)"
    )
    assert run(code) == "False"


def test_the_trainer_brings_torch() -> None:
    assert run("import sys; from learner import Trainer; print('torch' in sys.modules)") == "True"


def test_the_command_line_parses_without_torch() -> None:
    """`ideeprl --help`, `backup`, `export` start at once: making the parser (every run field
    a flag) loads neither torch nor the simulator."""
    code = (
        "import sys; from cli.main import build_parser; build_parser(); "
        "print(any(m in sys.modules for m in ('torch', 'pybullet')))"
    )
    assert run(code) == "False"
