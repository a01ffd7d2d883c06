"""One recorded episode rerun for the dashboard's playback, in a process of its own.

The web process loads no simulation, so it hands a `RerunOrder` (the session's run, the
episode's reset seed and its logged actions and rewards) to a spawned process, which
resets the environment with the seed, takes the logged actions (the environment is
deterministic), and sends back one `Rerun`: the scene's bodies, the poses before the
first step, and per step the image the learner saw, the motion and the poses after (a task
without a live 3-D view has no bodies: its steps' images are the playback).
Then it exits: the page steps through what it got, and the web process keeps nothing
running for it.
"""

from __future__ import annotations

import logging
import traceback
from collections.abc import Sequence
from dataclasses import dataclass, field
from multiprocessing.connection import Connection

from learner.run import RunSpec
from runs.worker.messages import SceneReset, SceneStep
from runs.worker.scene import scene_of

log = logging.getLogger(__name__)
REWARD_TOLERANCE = 1e-9


@dataclass(frozen=True)
class RerunOrder:
    """What a rerun needs, read from the database by the web process."""

    spec: RunSpec
    """The session's run, as the web process read it."""
    reset_seed: int
    actions: Sequence[int]
    """The episode's logged actions, in order."""
    rewards: Sequence[float]
    """Their logged rewards: the rerun checks it reproduces them."""


@dataclass(frozen=True)
class RerunStep:
    observation_png: bytes
    """The 64x64 image the learner saw when the step's action was chosen (PNG, lossless)."""
    scene: SceneStep
    """The step's motion and the poses after it, as the live view gets them."""
    reward: float
    """The reward the rerun gave (equal to the logged one, or `Rerun.mismatch` says where)."""


@dataclass(frozen=True)
class Rerun:
    start: SceneReset
    """The scene's bodies and their poses after the reset."""
    steps: list[RerunStep] = field(default_factory=list)
    final_png: bytes = b""
    """The image after the last step: the episode's end, which no action follows."""
    mismatch: str = ""
    """Empty when every reward equals the logged one; else which step differs (the session
    ran with another environment than its run describes)."""


@dataclass(frozen=True)
class RerunFailed:
    """Why the rerun could not be made (the worker's own error, for the researcher)."""

    detail: str


def rerun_episode(order: RerunOrder) -> Rerun:
    """Reset with the episode's seed and take its logged actions."""
    from study.services.observations import encode_observation  # the rerun's process only

    env = order.spec.make_env(record_motion=True)
    try:
        obs, _ = env.reset(seed=order.reset_seed)
        scene = scene_of(env) if order.spec.the_task.live_view else None
        frame = env.render if getattr(env, "render_mode", None) == "rgb_array" else None
        start = SceneReset(
            bodies=list(scene.scene_bodies()) if scene else [],
            poses=dict(scene.body_poses()) if scene else {},
            episode=-1,
        )
        steps: list[RerunStep] = []
        mismatch = ""
        for index, (action, logged) in enumerate(zip(order.actions, order.rewards, strict=True)):
            seen = encode_observation(obs, frame)
            obs, reward, _, _, _ = env.step(int(action))
            if not mismatch and abs(float(reward) - float(logged)) > REWARD_TOLERANCE:
                mismatch = f"step {index + 1}: the rerun's reward {reward:g}, logged {logged:g}"
            motion = SceneStep(
                action=int(action),
                reward=float(reward),
                frames=list(getattr(scene, "last_motion", None) or []),
                poses=dict(scene.body_poses()) if scene else {},
                global_step=index + 1,
            )
            steps.append(RerunStep(seen, motion, float(reward)))
        return Rerun(start, steps, encode_observation(obs, frame), mismatch)
    finally:
        env.close()


def rerun_main(conn: Connection, order: RerunOrder) -> None:
    """The process' target: one rerun, sent back, then exit."""
    try:
        result: Rerun | RerunFailed = rerun_episode(order)
    except Exception as error:  # the researcher sees why, not a stuck page
        log.error("rerun failed:\n%s", traceback.format_exc())
        result = RerunFailed(f"{type(error).__name__}: {error}")
    try:
        conn.send(result)
    except (BrokenPipeError, OSError):
        pass  # the page closed while the rerun ran
    finally:
        conn.close()
