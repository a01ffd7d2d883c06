"""Playback of the robot's motion between the frames PyBullet recorded."""

from __future__ import annotations

import numpy as np
import pytest

import sim
from runs.worker.messages import SceneStep
from server.viewer.playback import motion_duration, pose_at


@pytest.fixture(scope="module")
def motions() -> dict[str, list[sim.MotionFrame]]:
    found = {}
    for motion in ("physics", "fast"):
        env = sim.SortingEnv(motion=motion, record_motion=True)
        env.reset(seed=4)
        env.step(sim.Action.GRAB)
        found[motion] = list(env.unwrapped.last_motion)
        env.close()
    return found


def _position(frame_poses: dict[str, sim.Pose], name: str) -> np.ndarray:
    return np.asarray(frame_poses[name].position)


@pytest.mark.parametrize("motion", ["physics", "fast"])
def test_playback_passes_through_the_recorded_frames(motions, motion: str) -> None:
    frames = motions[motion]
    assert len(frames) >= 2
    for frame in frames:
        shown = pose_at(frames, frame.time)
        for name, pose in frame.poses.items():
            assert np.allclose(_position(shown, name), pose.position, atol=1e-9)
    assert pose_at(frames, -1.0) == dict(frames[0].poses)
    assert pose_at(frames, frames[-1].time + 5) == dict(frames[-1].poses)


def test_between_frames_the_arm_is_between_them(motions) -> None:
    a, b = motions["fast"][0], motions["fast"][-1]  # 0.5 s apart in the fast mode
    middle = pose_at(motions["fast"], (a.time + b.time) / 2)
    for name in ("arm/link_7", "arm/suction_cup"):
        pa, pb, pm = _position(a.poses, name), _position(b.poses, name), _position(middle, name)
        assert np.allclose(pm, (pa + pb) / 2, atol=1e-9)
        assert np.isclose(np.linalg.norm(middle[name].orientation), 1.0)


def test_motion_duration_is_the_last_frame_time(motions) -> None:
    frames = motions["physics"]
    step = SceneStep(action=0, reward=0.0, frames=frames, poses={}, global_step=1)
    assert motion_duration(step) == pytest.approx(frames[-1].time) and frames[-1].time > 0.2
    assert motion_duration(SceneStep(0, 0.0, frames[:1], {}, 1)) == 0.0
