"""mypy over the packages (`[tool.mypy]` in pyproject.toml), held to a baseline that may only
shrink: `sim/`, `learner/` and the core (`study/`: db, services, schemas, settings) have
no errors; elsewhere each file may have at most the errors `mypy-baseline.txt` lists
for it. `python -m tests.mypy_baseline` checks (run by `make lint`; tests/test_types.py runs
it too); `--update` writes the baseline anew after errors were fixed."""

from __future__ import annotations

import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).absolute().parents[1]
BASELINE = ROOT / "mypy-baseline.txt"
CLEAN = ("sim/", "learner/", "study/")
"""Where no error may be: the parts both processes (and the analysis) build on."""
ERROR = re.compile(r"^(?P<path>[^:\s]+\.py):\d+: error: ")


def run_mypy() -> tuple[Counter[str], str]:
    """Errors per file, and mypy's own output (for the message)."""
    done = subprocess.run(
        [sys.executable, "-m", "mypy"], cwd=ROOT, capture_output=True, text=True, check=False
    )
    if done.returncode not in (0, 1):  # 2: mypy itself failed (config, crash)
        raise RuntimeError(f"mypy failed:\n{done.stdout}{done.stderr}")
    errors = Counter(m["path"] for line in done.stdout.splitlines() if (m := ERROR.match(line)))
    return errors, done.stdout


def read_baseline() -> Counter[str]:
    counts: Counter[str] = Counter()
    for line in BASELINE.read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            path, count = line.rsplit(" ", 1)
            counts[path] = int(count)
    return counts


def write_baseline(errors: Counter[str]) -> None:
    lines = [f"{path} {count}" for path, count in sorted(errors.items())]
    header = "# mypy errors allowed per file (tests/mypy_baseline.py): may only shrink\n"
    BASELINE.write_text(header + "\n".join(lines) + "\n")


def problems(errors: Counter[str], baseline: Counter[str]) -> list[str]:
    """What breaks the rule: an error where none may be, or more than the baseline allows."""
    found = []
    for path, count in sorted(errors.items()):
        if path.startswith(CLEAN):
            found.append(f"{path}: {count} error(s), and this part must have none")
        elif count > baseline[path]:
            found.append(f"{path}: {count} error(s), the baseline allows {baseline[path]}")
    return found


def main(argv: list[str]) -> int:
    errors, output = run_mypy()
    if "--update" in argv:
        write_baseline(Counter({p: n for p, n in errors.items() if not p.startswith(CLEAN)}))
    baseline = read_baseline()
    found = problems(errors, baseline)
    if found:
        print(output + "\nNew type errors:\n" + "\n".join(found))
        return 1
    fewer = sum(baseline.values()) - sum(errors.values())
    if fewer > 0:
        print(f"{fewer} fewer errors than mypy-baseline.txt: run with --update to keep it so")
    print(f"mypy: {sum(errors.values())} errors, none new")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
