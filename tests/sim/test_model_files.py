"""The robot's model files: written where only this user can change them, read by anyone's run.

PyBullet loads the arm from files the package writes (simplified meshes, the URDF). They
once went to one /tmp/ideeprl-sim for every user, mode 0600: after root had run the
platform, a service running as its own user failed every session with "Cannot load URDF
file". These tests build real environments from a temporary folder of their own.
"""

import os
import shutil
import stat
import tempfile
import traceback
from collections.abc import Iterator
from pathlib import Path

import pytest

import sim
from sim import meshes

NOBODY = 65534


@pytest.fixture
def temp_dir(
    monkeypatch: pytest.MonkeyPatch, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Path]:
    """A fresh system temporary folder, world-writable and sticky as /tmp is.

    Made beside pytest's own folders, which other users cannot enter; pytest's are placed
    first, since pytest too asks `tempfile` where they go.
    """
    tmp_path_factory.getbasetemp()
    base = Path(tempfile.mkdtemp(prefix="ideeprl-test-tmp-"))
    base.chmod(0o1777)
    monkeypatch.setattr(tempfile, "tempdir", str(base))
    meshes.arm_urdf.cache_clear()
    yield base
    meshes.arm_urdf.cache_clear()
    shutil.rmtree(base)


def build_the_robot() -> None:
    """Make and reset an environment, which loads the arm from its files."""
    env = sim.SortingEnv(motion="fast")
    try:
        env.reset(seed=0)
    finally:
        env.close()


def test_the_files_go_to_a_folder_of_this_user_that_only_it_can_open(temp_dir: Path) -> None:
    build_the_robot()
    folder = temp_dir / f"ideeprl-sim-{os.getuid()}"
    info = folder.lstat()
    assert stat.S_ISDIR(info.st_mode)
    assert (info.st_uid, stat.S_IMODE(info.st_mode)) == (os.getuid(), 0o700)
    assert list(folder.glob("*/iiwa_suction.urdf"))


@pytest.mark.parametrize("mode", [0o777, 0o770, 0o702])
def test_a_folder_that_others_may_change_is_passed_over(temp_dir: Path, mode: int) -> None:
    loose = temp_dir / f"ideeprl-sim-{os.getuid()}"
    loose.mkdir()
    loose.chmod(mode)
    build_the_robot()
    assert not list(loose.iterdir())
    chosen = meshes.model_folder()
    assert chosen != loose and chosen.parent == temp_dir
    assert stat.S_IMODE(chosen.stat().st_mode) == 0o700


def test_a_link_in_the_folders_place_is_passed_over(temp_dir: Path, tmp_path: Path) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir(mode=0o700)
    (temp_dir / f"ideeprl-sim-{os.getuid()}").symlink_to(elsewhere)
    build_the_robot()
    assert not list(elsewhere.iterdir())


root_only = pytest.mark.skipif(os.getuid() != 0, reason="needs root to act as another user")


@root_only
def test_a_folder_another_user_made_is_passed_over(temp_dir: Path) -> None:
    theirs = temp_dir / f"ideeprl-sim-{os.getuid()}"
    theirs.mkdir(mode=0o700)
    os.chown(theirs, NOBODY, NOBODY)
    build_the_robot()
    assert not list(theirs.iterdir())
    assert meshes.model_folder() != theirs


@root_only
def test_another_user_builds_the_robot_after_root_did(temp_dir: Path) -> None:
    """The deployment's case: root ran the platform first, then the service's user."""
    build_the_robot()
    meshes.arm_urdf.cache_clear()
    pid = os.fork()
    if pid == 0:  # the child: the service's user, in the same temporary folder
        code = 1
        try:
            os.setgroups([])
            os.setgid(NOBODY)
            os.setuid(NOBODY)
            build_the_robot()
            code = 0
        except BaseException:
            traceback.print_exc()
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0, "another user could not load the arm's files"
