"""The reach task's environment: PyBullet's KUKA iiwa (pybullet_data's own URDF) brings its
hand to a red ball, one move a step along the world's axes.

The hand moves on a lattice of points `STEP` apart inside a box in front of the robot
(`LATTICE`); a move that would leave the box leaves the hand where it is. The arm follows
by inverse kinematics, set at once (no dynamics), so a step costs one solve and two small
renders. The ball sits on another point of the lattice; the episode succeeds, and ends,
when the hand reaches it.

Reward: 0.1 x (distance to the ball before the move - after it) / `STEP`, so +0.1 for a
move straight towards the ball and -0.1 for one straight away; and 1 more on reaching it.

The learner sees a 64x64 image made of two 64x32 views, from above (upper half) and from
the side (lower half), so that every axis of a move shows. People see the scene in 3-D
(`scene_bodies`, `body_poses`: every visual shape as PyBullet has it, `sim.visuals`).
"""

from __future__ import annotations

import contextlib
import functools
from typing import Any

import gymnasium as gym
import numpy as np
import pybullet_data

from sim import meshes
from sim.bodies import MotionFrame, Pose
from sim.bullet import pybullet
from sim.camera import Camera
from sim.layout import CameraPose
from sim.visuals import BulletScene
from sim.world import Client, World
from tasks.reach.moves import CAMERA, MOVES

STEP = 0.06
"""Metres the hand moves in one action."""
LATTICE = ((0.36, 5), (-0.18, 7), (0.2, 5))
"""Along x, y and z: the first point and the number of points; the hand and the ball sit
on them."""
HAND_LINK = 6
"""The iiwa's last link (`lbr_iiwa_link_7`), whose origin is the hand."""
HAND_DOWN = (0.0, 1.0, 0.0, 0.0)
"""The hand's orientation, pointing down (x, y, z, w)."""
REST = (0.0, 0.5, 0.0, -1.6, 0.0, 1.0, 0.0)
"""The iiwa's joints when a solve starts: elbow up, hand forward and down."""
IIWA_RGBA = (
    (0.2, 0.2, 0.2, 1.0),
    *[(0.5, 0.7, 1.0, 1.0)] * 2,
    (1.0, 0.4235, 0.0392, 1.0),
    *[(0.5, 0.7, 1.0, 1.0)] * 2,
    (1.0, 0.4235, 0.0392, 1.0),
    (0.2, 0.2, 0.2, 1.0),
)
"""The stock URDF's colours of links 0 to 7, kept."""
HULL_POINTS = 64
"""The camera's iiwa: each link the convex hull of 64 of its points (as the sorting robot's,
`sim.meshes`), a twentieth of the triangles and the same 64x64 image; people see the full
meshes."""
BALL_RADIUS = 0.035
BALL_RGBA = (0.9, 0.1, 0.08, 1.0)
FLOOR_RGBA = (0.78, 0.78, 0.74, 1.0)
TOP_VIEW = CameraPose(eye=(0.48, -0.3, 1.8), target=(0.48, 0.0, 0.2), fov=15.0)
SIDE_VIEW = CameraPose(eye=(0.48, -2.0, 0.32), target=(0.48, 0.0, 0.32), fov=11.0)
"""The learner's two views: each 64 wide and 32 high, framing the lattice's box (the
view from above leans a little, as a camera looking straight down has no "up")."""
PEOPLE_VIEW = CameraPose(eye=CAMERA.eye, target=CAMERA.target, fov=CAMERA.fov)
MOTION_S = 0.3
"""Simulated seconds a move takes in the 3-D view's replay of an advised step."""


def lattice_point(index: tuple[int, ...]) -> np.ndarray:
    return np.array([start + STEP * i for (start, _), i in zip(LATTICE, index, strict=True)])


@functools.cache
def lattice_distance(a: tuple[int, ...], b: tuple[int, ...]) -> float:
    """Metres between two lattice points; a step asks it three times, of at most 175 x 175
    pairs."""
    return float(np.linalg.norm(lattice_point(a) - lattice_point(b)))


class ReachEnv(gym.Env[np.ndarray, int]):
    """Reach the red ball with the iiwa's hand."""

    metadata = {"render_modes": ["rgb_array"]}  # noqa: RUF012 (Gymnasium's own attribute)

    def __init__(self, max_steps: int = 50, record_motion: bool = False) -> None:
        self.limit = max_steps
        self.record_motion = record_motion
        self.observation_space = gym.spaces.Box(0, 255, (64, 64, 3), np.uint8)
        self.action_space = gym.spaces.Discrete(len(MOVES))  # type: ignore[assignment]
        self.render_mode = "rgb_array"
        world = World()  # a PyBullet client; this task uses only its bodies and cameras
        world.p.setGravity(0, 0, 0)
        self.world, self.p = world, world.p
        self.arm, self.ball = self._build(self.p)
        self.scene = BulletScene(
            self.p,
            {"floor": self.floor, "arm": self.arm, "ball": self.ball},
            still=("floor",),
            shown_meshes={
                str(self._hull_folder / f"link_{link}.obj"): str(meshes.link_mesh_path(link))
                for link in range(meshes.ARM_LINKS)
            },
        )
        self._moving = frozenset(spec.name for spec in self.scene.specs if spec.moving)
        self._poses: dict[str, Pose] | None = None
        """Every shape's pose in the scene as it is, read from PyBullet once after each
        change: a step's motion starts where the last one ended, and the view's poses are
        the motion's end."""
        self.top = Camera(world, TOP_VIEW, 64, 32)
        self.side = Camera(world, SIDE_VIEW, 64, 32)
        self.people = Camera(world, PEOPLE_VIEW, 256)
        self.hand: tuple[int, ...] = (0, 0, 0)
        """The hand's lattice point (indices along x, y, z)."""
        self.goal: tuple[int, ...] = (0, 0, 0)
        """The ball's."""
        self._steps = 0
        self.last_motion: list[MotionFrame] = []

    def _build(self, p: Client) -> tuple[int, int]:
        p.setAdditionalSearchPath(pybullet_data.getDataPath())
        floor_shape = p.createVisualShape(
            pybullet.GEOM_BOX, halfExtents=(0.9, 0.7, 0.01), rgbaColor=FLOOR_RGBA
        )
        self.floor = p.createMultiBody(0, -1, floor_shape, (0.3, 0.0, -0.01))
        urdf = meshes.arm_urdf("", IIWA_RGBA, HULL_POINTS)
        self._hull_folder = urdf.parent
        arm = p.loadURDF(str(urdf), useFixedBase=True)
        ball_shape = p.createVisualShape(
            pybullet.GEOM_SPHERE, radius=BALL_RADIUS, rgbaColor=BALL_RGBA
        )
        ball = p.createMultiBody(0, -1, ball_shape, (0.5, 0.0, 0.3))
        return arm, ball

    # --- Gymnasium ---------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self._poses = None
        sizes = [n for _, n in LATTICE]
        self.hand = tuple(int(self.np_random.integers(n)) for n in sizes)
        self.goal = self.hand
        while self.goal == self.hand:
            self.goal = tuple(int(self.np_random.integers(n)) for n in sizes)
        self.p.resetBasePositionAndOrientation(self.ball, lattice_point(self.goal), (0, 0, 0, 1))
        for joint, angle in enumerate(REST):  # the same solve from the same seed
            self.p.resetJointState(self.arm, joint, angle)
        self._place_arm()
        self._steps = 0
        self.last_motion = [MotionFrame(0.0, self._moving_poses())]
        return self._observation(), self._info()

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if not self.action_space.contains(action):
            raise ValueError(f"reach actions are 0 to {len(MOVES) - 1}, got {action!r}")
        before = self.distance()
        start = self._moving_poses() if self.record_motion else None
        moved = tuple(h + d for h, d in zip(self.hand, MOVES[int(action)], strict=True))
        if all(0 <= i < n for i, (_, n) in zip(moved, LATTICE, strict=True)):
            self.hand = moved
            self._place_arm()
        self._steps += 1
        reached = self.hand == self.goal
        reward = 0.1 * (before - self.distance()) / STEP + (1.0 if reached else 0.0)
        truncated = self._steps >= self.limit and not reached
        if start is not None:
            self.last_motion = [
                MotionFrame(0.0, start),
                MotionFrame(MOTION_S, self._moving_poses()),
            ]
        return self._observation(), float(reward), reached, truncated, self._info()

    def render(self) -> np.ndarray:
        """What people see, 256x256, when a page shows frames."""
        return self.people.image()

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.world.close()

    # --- the state -----------------------------------------------------------------------
    def distance(self) -> float:
        """Metres from the hand's lattice point to the ball's."""
        return lattice_distance(self.hand, self.goal)

    def correct_action(self) -> int | None:
        """The move that brings the hand nearest the ball (the first such in action order);
        None once there."""
        if self.hand == self.goal:
            return None
        gaps = [abs(g - h) for g, h in zip(self.goal, self.hand, strict=True)]
        axis = int(np.argmax(gaps))
        return 2 * axis + (0 if self.goal[axis] > self.hand[axis] else 1)

    def hand_position(self) -> np.ndarray:
        """Where the arm's hand actually is (inverse kinematics is within millimetres)."""
        return np.array(self.p.getLinkState(self.arm, HAND_LINK)[4])

    def _info(self) -> dict[str, Any]:
        return {
            "hand": list(self.hand),
            "goal": list(self.goal),
            "distance": self.distance(),
            "correct_action": self.correct_action(),
            "is_success": self.hand == self.goal,
        }

    def _place_arm(self) -> None:
        target = lattice_point(self.hand).tolist()
        for _ in range(4):  # each solve starts where the last one left the arm
            q = self.p.calculateInverseKinematics(
                self.arm, HAND_LINK, target, HAND_DOWN, restPoses=list(REST),
                maxNumIterations=100, residualThreshold=1e-5,
            )  # fmt: skip
            for joint, angle in enumerate(q):
                self.p.resetJointState(self.arm, joint, angle)
        self._poses = None

    def _observation(self) -> np.ndarray:
        return np.concatenate([self.top.image(), self.side.image()], axis=0)

    # --- what the 3-D view needs ---------------------------------------------------------
    def scene_bodies(self) -> list[Any]:
        return list(self.scene.specs)

    def body_poses(self) -> dict[str, Pose]:
        if self._poses is None:
            self._poses = self.scene.poses()
        return dict(self._poses)

    def _moving_poses(self) -> dict[str, Pose]:
        return {name: pose for name, pose in self.body_poses().items() if name in self._moving}
