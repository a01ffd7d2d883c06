"""`analysis` names its public functions without importing them: each name it lists
resolves to its module's object on first use, and importing the package loads none."""

import subprocess
import sys

import analysis


def test_every_listed_name_resolves_to_its_module() -> None:
    for name in analysis.__all__:
        value = getattr(analysis, name)
        assert getattr(sys.modules[f"analysis.{analysis._MODULE_OF[name]}"], name) is value


def test_importing_the_package_loads_no_plotting_or_statistics() -> None:
    code = "import sys, analysis; print('matplotlib' in sys.modules, 'scipy' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["False", "False"]
