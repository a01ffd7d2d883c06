"""Playing the robot's motion to one viser client in real time.

A worker's `SceneStep` carries the step's motion as frames stamped with simulated time
(30 a second in the physics mode; before and after in the fast mode). A `Player` thread
per client shows them. Only a step that carried out the participant's own advice
(`SceneStep.advised`) is replayed as motion: at its timestamps (times `speed`),
interpolated at `tick_hz` so the arm moves smoothly however sparse the frames, ending at
the step's final poses. Every other step (the robot's random practice before the first
turn, its own moves between advice) is shown at once at its final poses, and a run of
them collapses into the latest, so the view is never behind and never holds back the
participant's turn (the page keeps its buttons off while `remaining_s` > 0). Advised steps
that arrive faster than they can be shown play faster, and with more waiting the view
jumps to the latest. Hub callbacks only `push`; all viser calls happen on the player's
thread.
"""

from __future__ import annotations

import itertools
import logging
import threading
import time
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

import sim
from runs.worker.messages import SceneReset, SceneStep
from server.viewer.mirror import SceneMirror

log = logging.getLogger(__name__)
JUMP_BACKLOG = 3
"""With this many steps still waiting, a step is shown at its end pose without motion."""


def _lerp_pose(a: sim.Pose, b: sim.Pose, alpha: float) -> sim.Pose:
    pa, pb = np.asarray(a.position), np.asarray(b.position)
    qa, qb = np.asarray(a.orientation), np.asarray(b.orientation)
    if float(np.dot(qa, qb)) < 0.0:
        qb = -qb
    q = (1.0 - alpha) * qa + alpha * qb
    q /= np.linalg.norm(q) or 1.0
    p = (1.0 - alpha) * pa + alpha * pb
    return sim.Pose(tuple(p.tolist()), tuple(q.tolist()))


def pose_at(frames: Sequence[sim.MotionFrame], t: float) -> dict[str, sim.Pose]:
    """The moving bodies' poses at simulated time `t` of a step's motion."""
    assert frames, "a motion has at least one frame"
    if t <= frames[0].time:
        return dict(frames[0].poses)
    for before, after in itertools.pairwise(frames):
        if t < after.time:
            span = after.time - before.time
            alpha = (t - before.time) / span if span > 0 else 1.0
            return {
                name: _lerp_pose(pose, after.poses.get(name, pose), alpha)
                for name, pose in before.poses.items()
            }
    return dict(frames[-1].poses)


def motion_duration(step: SceneStep) -> float:
    """Simulated seconds the step's motion lasts (0 when nothing moved)."""
    return float(step.frames[-1].time) if len(step.frames) > 1 else 0.0


@dataclass(frozen=True)
class Item:
    """A scene event waiting to be shown; `instant` ones skip the motion (late joiners)."""

    message: SceneReset | SceneStep
    instant: bool = False

    @property
    def moves(self) -> bool:
        """Shown as motion: the participant's own advised step, with motion to show."""
        message = self.message
        return (
            isinstance(message, SceneStep)
            and message.advised
            and not self.instant
            and motion_duration(message) > 0.0
        )

    @property
    def jumps(self) -> bool:
        """A step shown at its final poses only."""
        return isinstance(self.message, SceneStep) and not self.moves


class Player:
    """One client's playback thread."""

    def __init__(self, mirror: SceneMirror, speed: float = 1.0, tick_hz: float = 30.0) -> None:
        assert speed > 0 and tick_hz > 0
        self.mirror = mirror
        self.speed = speed
        self.tick_s = 1.0 / tick_hz
        self.updates = 0
        """Pose updates sent so far (frames of motion and final poses)."""
        self.steps_received = 0
        """Scene steps pushed to this view so far."""
        self.steps_animated = 0
        """Steps shown as motion (the participant's advised ones) so far."""
        self._queue: deque[Item] = deque()
        self._cond = threading.Condition()
        self._playing_until = 0.0
        """When the item being shown should be done (0: none is); building a scene can
        outlast it."""
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="viewer-player", daemon=True)

    def start(self) -> Player:
        self._thread.start()
        return self

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def join(self, timeout: float | None = None) -> None:
        self._thread.join(timeout)

    def push(self, message: SceneReset | SceneStep, instant: bool = False) -> None:
        """Queue a scene event (from any thread; returns at once)."""
        with self._cond:
            self._queue.append(Item(message, instant))
            if isinstance(message, SceneStep):
                self.steps_received += 1
            self._cond.notify_all()

    def remaining_s(self) -> float:
        """Real seconds until everything queued has been shown (an estimate when
        fast-forwarding)."""
        with self._cond:
            now = time.monotonic()
            left = max(0.0, self._playing_until - now)
            if self._playing_until:  # an item is still being shown, however long it takes
                left = max(left, self.tick_s)
            steps = [i.message for i in self._queue if i.moves]
            if len(steps) < JUMP_BACKLOG:
                moving = (motion_duration(s) for s in steps if isinstance(s, SceneStep))
                left += sum(moving) / self.speed
            return left + (self.tick_s if self._queue else 0.0)

    def idle(self) -> bool:
        return self.remaining_s() == 0.0

    # --- the thread ------------------------------------------------------------------
    def _next(self) -> tuple[Item, int] | None:
        with self._cond:
            while not self._queue and not self._closed:
                self._cond.wait()
            if self._closed:
                return None
            item = self._queue.popleft()
            while item.jumps and self._queue and self._queue[0].jumps:
                item = self._queue.popleft()  # each step carries every pose: the latest will do
            backlog = sum(1 for i in self._queue if i.moves)
            # Busy from the moment it is taken, so `remaining_s` never reads 0 in between.
            self._playing_until = time.monotonic() + self.tick_s
            if self._animated(item, backlog):
                duration = motion_duration(item.message)  # type: ignore[arg-type]
                self._playing_until += duration / (self.speed * (1 + backlog))
            return item, backlog

    @staticmethod
    def _animated(item: Item, backlog: int) -> bool:
        return item.moves and backlog < JUMP_BACKLOG

    def _run(self) -> None:
        while True:
            taken = self._next()
            if taken is None:
                return
            item, backlog = taken
            try:
                self._show(item, backlog)
            except Exception:
                log.exception("viewer playback failed; the scene may lag until the next step")
            finally:
                with self._cond:
                    self._playing_until = 0.0

    def _show(self, item: Item, backlog: int) -> None:
        message = item.message
        if isinstance(message, SceneReset):
            self.mirror.build(list(message.bodies))
            self._apply(message.poses)
            return
        if not self._animated(item, backlog):
            self._apply(message.poses)
            time.sleep(self.tick_s)  # at most one update a tick, however fast steps come
            return
        self.steps_animated += 1
        duration = motion_duration(message)
        speed = self.speed * (1 + backlog)
        start = time.monotonic()
        while not self._closed:
            tick = time.monotonic()
            t = (tick - start) * speed
            if t >= duration:
                break
            self._apply(pose_at(message.frames, t))
            time.sleep(max(0.0, tick + self.tick_s - time.monotonic()))
        self._apply(message.poses)

    def _apply(self, poses: Mapping[str, Any]) -> None:
        if self._closed:
            return  # the client has gone: viser would only warn
        self.mirror.apply(poses)
        self.updates += 1
