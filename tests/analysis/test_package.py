"""`analysis` names its public functions without importing them: each name it lists
resolves to its module's object on first use, and importing the package loads none; and
none of its modules, imported or auditing a run, loads the runtime (torch, the simulation,
the learner's trainers)."""

import subprocess
import sys
from pathlib import Path

import analysis

ROOT = Path(__file__).absolute().parents[2]


def test_every_listed_name_resolves_to_its_module() -> None:
    for name in analysis.__all__:
        value = getattr(analysis, name)
        assert getattr(sys.modules[f"analysis.{analysis._MODULE_OF[name]}"], name) is value


def test_importing_the_package_loads_no_plotting_or_statistics() -> None:
    code = "import sys, analysis; print('matplotlib' in sys.modules, 'scipy' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["False", "False"]


RUNTIME = (
    "torch",
    "pybullet",
    "stable_baselines3",
    "learner.sb3_dqn",
    "learner.trainer",
    "learner.agent",
    "sim.bullet",
    "sim.env",
)
"""What the analysis (a library read at report time) must not load: the learner's torch and
trainers, the SB3 baseline, the simulation."""
IMPORT_ALL = """
import importlib, pkgutil
import analysis
names = [m.name for m in pkgutil.walk_packages(analysis.__path__, "analysis.")]
for name in names:
    importlib.import_module(name)
print(len(names))
"""
AUDIT_SB3 = """
from analysis.settings import settings_table
from learner.run import RunSpec
print(settings_table([(1, RunSpec(method="sb3-dqn"))]).loc[0, "learner"])
"""
LOADED = """
import sys
print(*sorted(n for n in sys.modules if n in sys.argv[1:]))
"""


def _run_in_fresh_process(code: str) -> tuple[str, list[str]]:
    """`code`'s output, and which of `RUNTIME` it left in `sys.modules`."""
    done = subprocess.run(
        [sys.executable, "-c", code + LOADED, *RUNTIME],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    *output, loaded = done.stdout.splitlines()
    return "\n".join(output), loaded.split()


def test_importing_every_analysis_module_loads_nothing_of_the_runtime() -> None:
    """Every module of the package, imported in a fresh process, leaves torch, pybullet,
    SB3 and the learner's and simulation's runtime modules out of `sys.modules` (the
    import-linter contract `analysis` checks the static graph; this, what runs)."""
    count, loaded = _run_in_fresh_process(IMPORT_ALL)
    assert int(count) > 10  # the walk found the package's modules
    assert not loaded, f"importing analysis loads {loaded}"


def test_auditing_an_sb3_run_loads_nothing_of_the_runtime() -> None:
    """The audit describes an `sb3-dqn` run from its torch-free spec (`learner.sb3_spec`),
    not from the trainer's module, which a function-level import would load unseen by the
    static contract."""
    learner, loaded = _run_in_fresh_process(AUDIT_SB3)
    assert learner.startswith("sb3-dqn (Stable-Baselines3 DQN: batch_size=128,"), learner
    assert not loaded, f"the audit of an sb3-dqn run loads {loaded}"
