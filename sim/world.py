"""One PyBullet client and the names of the bodies in it.

Everything else in the package talks to PyBullet through a `World`, so each environment
owns exactly one client (several environments can live in one process) and every body has
a viewer-friendly name that `scene_bodies()`, `body_poses()` and `last_motion` share.
"""

import contextlib
import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from sim.bodies import BodySpec, Box, Color, Cylinder, Mesh, MotionFrame, Pose
from sim.bullet import pybullet

TIME_STEP = 1.0 / 120.0
"""Seconds of simulated time per physics step: half PyBullet's default step, twice as fast,
still stable for 0.1 kg objects on a table."""
SOLVER_ITERATIONS = 20
SOLVER_RESIDUAL = 1e-4
"""Fewer solver iterations than PyBullet's 50, stopping once the residual is this small: a
quarter less time per step with objects resting on tables, and no difference a person or
the task can see (the oracle still sorts every seed of the tests perfectly)."""
RECORD_EVERY = 4
"""Physics steps between two recorded motion frames: 30 frames per simulated second."""


@dataclass(frozen=True)
class Part:
    """Where a named body is kept: a PyBullet base or link, or a fixed pose."""

    body: int
    """PyBullet body id, or -1 for a prop only the viewer shows (the camera)."""
    link: int
    """Link index, -1 for the base."""
    fixed_pose: Pose | None = None
    """The pose of a body that never moves, when PyBullet cannot tell it: a prop, or the
    arm's base, whose mesh frame is not the centre of mass PyBullet reports."""


def wxyz(xyzw: tuple[float, ...] | list[float]) -> tuple[float, float, float, float]:
    return (float(xyzw[3]), float(xyzw[0]), float(xyzw[1]), float(xyzw[2]))


class Client:
    """PyBullet's functions bound to one headless physics client (`client.stepSimulation()`).

    Like pybullet_utils' BulletClient, without its `argv[0]=` print on every connect.
    """

    def __init__(self) -> None:
        self.id = pybullet.connect(pybullet.DIRECT)

    def __getattr__(self, name: str) -> Any:
        function = functools.partial(getattr(pybullet, name), physicsClientId=self.id)
        setattr(self, name, function)  # found directly from now on
        return function

    def close(self) -> None:
        if self.id >= 0:
            pybullet.disconnect(physicsClientId=self.id)
            self.id = -1

    def __deepcopy__(self, memo: dict[int, Any]) -> "Client":
        raise TypeError(
            "a PyBullet client cannot be copied: the copy would share its connection and "
            "disconnect it when collected; copy the SortingEnv instead (it builds its own)"
        )

    def __reduce__(self) -> tuple[Any, ...]:
        raise TypeError(
            "a PyBullet client cannot be pickled; pickle the SortingEnv instead (it is "
            "rebuilt with its own connection)"
        )

    def __del__(self) -> None:
        with contextlib.suppress(Exception):  # interpreter shutdown may have removed pybullet
            self.close()


class World:
    """A headless PyBullet simulation whose bodies have names."""

    def __init__(self) -> None:
        self.p = Client()
        self.parts: dict[str, Part] = {}
        self.specs: list[BodySpec] = []
        self.time = 0.0
        self.recording: list[MotionFrame] | None = None
        self._steps = 0
        self.reset()

    def reset(self) -> None:
        """Empty the simulation, as if freshly connected: rebuilding after this gives the
        same body ids and, step for step, the same physics as a new `World`."""
        self.p.resetSimulation()
        self.p.setGravity(0, 0, -9.81)
        self.p.setPhysicsEngineParameter(
            fixedTimeStep=TIME_STEP,
            deterministicOverlappingPairs=1,
            numSolverIterations=SOLVER_ITERATIONS,
            solverResidualThreshold=SOLVER_RESIDUAL,
        )
        self.parts.clear()
        self.specs.clear()

    def close(self) -> None:
        self.p.close()

    def add_box(
        self,
        name: str,
        half_extents: tuple[float, float, float],
        position: tuple[float, float, float],
        rgba: Color,
        mass: float = 0.0,
        collide: bool = True,
    ) -> int:
        collision = (
            self.p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half_extents)
            if collide
            else -1
        )
        visual = self.p.createVisualShape(
            pybullet.GEOM_BOX, halfExtents=half_extents, rgbaColor=rgba
        )
        body = self._create(mass, collision, visual, position)
        self._register(name, Part(body, -1), Box(np.asarray(half_extents, float)), rgba, mass > 0)
        return body

    def add_cylinder(
        self,
        name: str,
        radius: float,
        length: float,
        position: tuple[float, float, float],
        rgba: Color,
        mass: float,
    ) -> int:
        collision = self.p.createCollisionShape(
            pybullet.GEOM_CYLINDER, radius=radius, height=length
        )
        visual = self.p.createVisualShape(
            pybullet.GEOM_CYLINDER, radius=radius, length=length, rgbaColor=rgba
        )
        body = self._create(mass, collision, visual, position)
        self._register(name, Part(body, -1), Cylinder(radius, length), rgba, mass > 0)
        return body

    def _create(
        self, mass: float, collision: int, visual: int, position: tuple[float, float, float]
    ) -> int:
        """A single-link body. Moving ones are plain rigid bodies that may sleep when at rest:
        six objects resting on a table then cost a fraction of what multibodies would."""
        if mass == 0:
            return self.p.createMultiBody(mass, collision, visual, position)
        body = self.p.createMultiBody(mass, collision, visual, position)
        self.p.changeDynamics(body, -1, activationState=pybullet.ACTIVATION_STATE_ENABLE_SLEEPING)
        return body

    def add_part(
        self, name: str, part: Part, geometry: Box | Cylinder | Mesh, rgba: Color, moving: bool
    ) -> None:
        """Name a link (or base) of a body loaded some other way, e.g. from a URDF."""
        self._register(name, part, geometry, rgba, moving)

    def _register(
        self, name: str, part: Part, geometry: Box | Cylinder | Mesh, rgba: Color, moving: bool
    ) -> None:
        assert name not in self.parts, f"two bodies named {name}"
        self.parts[name] = part
        self.specs.append(BodySpec(name, geometry, rgba, moving))

    def poses(self, names: list[str] | None = None) -> dict[str, Pose]:
        """World poses of the named bodies (all when `names` is None)."""
        names = list(self.parts) if names is None else names
        poses: dict[str, Pose] = {}
        links: dict[int, list[tuple[str, int]]] = {}
        for name in names:
            part = self.parts[name]
            if part.link >= 0:
                links.setdefault(part.body, []).append((name, part.link))
            elif part.fixed_pose is not None:
                poses[name] = part.fixed_pose
            else:
                position, orientation = self.p.getBasePositionAndOrientation(part.body)
                poses[name] = Pose(tuple(position), wxyz(orientation))
        for body, named in links.items():
            states = self.p.getLinkStates(
                body, [link for _, link in named], computeForwardKinematics=True
            )
            for (name, _), state in zip(named, states, strict=True):
                poses[name] = Pose(tuple(state[4]), wxyz(state[5]))
        return {name: poses[name] for name in names}

    def moving_names(self) -> list[str]:
        return [spec.name for spec in self.specs if spec.moving]

    def step(self) -> None:
        """One physics step; records a motion frame every `RECORD_EVERY` steps when asked."""
        self.p.stepSimulation()
        self._steps += 1
        self.time += TIME_STEP
        if self.recording is not None and self._steps % RECORD_EVERY == 0:
            self.record()

    def record(self) -> None:
        """Add the moving bodies' current poses to the recording, if one is under way."""
        if self.recording is not None:
            self.recording.append(MotionFrame(self.time, self.poses(self.moving_names())))

    def start_recording(self) -> None:
        self.time = 0.0
        self._steps = 0
        self.recording = []
        self.record()

    def stop_recording(self, pause: float = 0.0) -> list[MotionFrame]:
        """The frames since `start_recording`, ending with the pose after the motion.

        `pause` (simulated seconds) stamps the final frame when nothing was simulated, so a
        viewer still animates a move that the fast mode made in one jump.
        """
        assert self.recording, "stop_recording without start_recording"
        frames, self.recording = self.recording, None
        final_time = max(self.time, frames[-1].time + pause)
        if frames[-1].time < final_time:
            frames.append(MotionFrame(final_time, self.poses(self.moving_names())))
        return frames
