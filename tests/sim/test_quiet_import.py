"""A process that builds a scene writes nothing to the terminal: PyBullet's build banner
(written from C to stderr when pybullet is imported) would break the line a batch's
progress bar redraws, once per worker."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).absolute().parents[2]
WORKER_LIKE = """
import sim
env = sim.SortingEnv(motion="fast", max_episode_steps=5)
env.reset(seed=0)
env.step(0)
env.close()
second = sim.SortingEnv(motion="fast")
second.reset(seed=1)
second.close()
"""


def test_a_worker_like_process_prints_nothing_when_it_builds_a_scene() -> None:
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
    }
    done = subprocess.run(
        [sys.executable, "-c", WORKER_LIKE], cwd=ROOT, env=env, capture_output=True, timeout=120
    )
    assert done.returncode == 0, done.stderr.decode()
    assert done.stdout == b"", done.stdout
    assert b"pybullet build time" not in done.stderr, done.stderr


def test_python_output_around_the_quiet_import_is_kept() -> None:
    script = (
        "print('before', flush=True)\nimport sim.world\nsim.world.Client().close()\nprint('after')"
    )
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
    }
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=ROOT, env=env, capture_output=True, timeout=120
    )
    assert done.stdout.decode().split() == ["before", "after"], done
