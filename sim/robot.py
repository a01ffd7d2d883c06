"""The KUKA iiwa with a suction cup: stations, inverse kinematics, suction.

Two ways to move, the same poses: `physics` drives the joints with position control
through simulated steps (each move capped by a step budget, never by wall-clock time) and
picks by a fixed constraint made when the cup touches an object; `fast` sets the same
joint configurations directly and carries the held object along. Every pose a move ends
at is solved once per layout (`Reach`), so both modes, and every environment in a
process, agree on them exactly.
"""

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sim import meshes
from sim.bodies import Color, Cylinder, Mesh, Pose
from sim.bullet import pybullet
from sim.layout import Layout
from sim.world import TIME_STEP, Part, World

STATIONS: tuple[str, ...] = ("center", "left", "right")
JOINTS = 7
CUP_LINK = 7
"""PyBullet link index of the suction cup (after the seven revolute joints)."""
CUP_RADIUS = 0.02
CUP_LENGTH = 0.12
CUP_RGBA: Color = (0.12, 0.12, 0.13, 1.0)
LINK_RGBA: tuple[Color, ...] = tuple(
    (0.32, 0.33, 0.36, 1.0) if link in (0, 3, 6, 7) else (0.9, 0.9, 0.88, 1.0) for link in range(8)
)
"""Greys: the stock orange and light blue would read as red and blue objects at 64x64."""
DOWN = pybullet.getQuaternionFromEuler((math.pi, 0.0, math.pi))
"""The cup pointing at the floor, with a fixed yaw (the iiwa's natural one above the center
table) so held objects keep their heading."""
REST_POSE = (0.0, 0.75, 0.0, -1.5, 0.0, 0.9, 0.0)
"""Elbow up: where IK for a station starts (turned towards it) and the posture it keeps."""
JOINT_SPEED = 4.0
"""Fastest joint speed along a move, rad/s."""
DESCENT_SPEED = 0.5
"""Fraction of `JOINT_SPEED` for lowering the cup onto an object or a table."""
MOVE_BUDGET = 120
"""Most physics steps one move may take, settling included (1 simulated second)."""
SETTLE_TOLERANCE = 0.01
"""Radians: a move is over when every joint is this close to its goal."""
POSITION_GAIN = 0.3
"""PyBullet's position-control gain: with the velocity fed forward the arm stays within a
hundredth of a radian of its path, yet yields to a collision."""
MOTOR_FORCE = 300.0
"""Newton metres, the iiwa URDF's effort limit."""
GRASP_DEPTH = 0.005
"""How far above a table top the cup's tip aims when lowering (contact stops it before)."""
RELEASE_GAP = 0.01
"""Height above the table at which a held object is let go, metres."""


@dataclass(frozen=True)
class Reach:
    """Joint configurations solved once per layout: every pose a motion starts or ends at."""

    station: dict[str, np.ndarray]
    """Cup at each station (`Layout.station`), at the hover height."""
    grid_hover: tuple[np.ndarray, ...]
    """Cup above each of the 9 grid positions at the hover height."""
    grid_low: tuple[np.ndarray, ...]
    """Cup just above the center table at each grid position."""
    slot_hover: dict[str, tuple[np.ndarray, ...]]
    """Cup above each drop slot of each side table at the hover height."""
    slot_low: dict[str, tuple[np.ndarray, ...]]
    """Cup just above each drop slot."""


_REACH: dict[Layout, Reach] = {}


_CUP_XML = f"""
  <joint name="suction_cup_joint" type="fixed">
    <parent link="lbr_iiwa_link_7"/>
    <child link="suction_cup"/>
    <origin rpy="0 0 0" xyz="0 0 {0.045 + CUP_LENGTH / 2}"/>
  </joint>
  <link name="suction_cup">
    <inertial>
      <origin rpy="0 0 0" xyz="0 0 0"/>
      <mass value="0.1"/>
      <inertia ixx="0.0001" ixy="0" ixz="0" iyy="0.0001" iyz="0" izz="0.0001"/>
    </inertial>
    <visual>
      <geometry><cylinder radius="{CUP_RADIUS}" length="{CUP_LENGTH}"/></geometry>
      <material name="cup"><color rgba="{" ".join(map(str, CUP_RGBA))}"/></material>
    </visual>
    <collision>
      <geometry><cylinder radius="{CUP_RADIUS}" length="{CUP_LENGTH}"/></geometry>
    </collision>
  </link>"""


class SuctionArm:
    """The arm, where it is, and what it holds."""

    def __init__(
        self, world: World, layout: Layout, physics: bool, half_heights: dict[int, float]
    ) -> None:
        """`half_heights`: each object's body id and half height (objects stand upright)."""
        self.world = world
        self.half_heights = half_heights
        self.p = world.p
        self.layout = layout
        self.physics = physics
        self.base_position = (0.0, 0.0, layout.table_height)
        urdf = meshes.arm_urdf(_CUP_XML, LINK_RGBA, hull_points=64)
        self.body = self.p.loadURDF(str(urdf), self.base_position, useFixedBase=True)
        assert self.p.getNumJoints(self.body) == JOINTS + 1
        info = [self.p.getJointInfo(self.body, j) for j in range(JOINTS)]
        self.lower = np.array([i[8] for i in info])
        self.upper = np.array([i[9] for i in info])
        self._register_parts()
        if layout not in _REACH:
            _REACH[layout] = self._solve_reach()
        self.reach = _REACH[layout]

        self.station = "center"
        self.held: int | None = None
        """Body id of the held object."""
        self._constraint: int | None = None
        self._held_offset: tuple[tuple[float, ...], tuple[float, ...]] | None = None
        self.set_joints(self.reach.station["center"])

    def _register_parts(self) -> None:
        self.world.add_part(
            "arm/link_0",
            Part(self.body, -1, fixed_pose=Pose(self.base_position, (1.0, 0.0, 0.0, 0.0))),
            Mesh(*meshes.read_obj(meshes.link_mesh_path(0))),
            LINK_RGBA[0],
            moving=False,
        )
        for link in range(1, meshes.ARM_LINKS):
            self.world.add_part(
                f"arm/link_{link}",
                Part(self.body, link - 1),
                Mesh(*meshes.read_obj(meshes.link_mesh_path(link))),
                LINK_RGBA[link],
                moving=True,
            )
        self.world.add_part(
            "arm/suction_cup",
            Part(self.body, CUP_LINK),
            Cylinder(CUP_RADIUS, CUP_LENGTH),
            CUP_RGBA,
            moving=True,
        )

    # -- kinematics -------------------------------------------------------------------

    def _solve(self, tip: tuple[float, float, float], start: np.ndarray | None) -> np.ndarray:
        """Joint angles that put the cup's tip at `tip`, pointing down, near `start`.

        PyBullet's IK walks from the arm's current joint angles and is pulled towards its
        rest poses; both are `start` (the arm is first set there, and the caller puts it
        back), or the arm's present angles when `start` is None (a live correction in the
        physics mode, which must not teleport the arm). The walk converges slowly, hence
        200 iterations (about 2 ms).
        """
        if start is None:
            start = self.joints()
        else:
            self.set_joints(start)
        solution = self.p.calculateInverseKinematics(
            self.body, CUP_LINK, (tip[0], tip[1], tip[2] + CUP_LENGTH / 2), DOWN,
            lowerLimits=list(self.lower), upperLimits=list(self.upper),
            jointRanges=list(self.upper - self.lower), restPoses=list(start),
            maxNumIterations=200, residualThreshold=1e-6,
        )  # fmt: skip
        return np.clip(np.array(solution[:JOINTS]), self.lower, self.upper)

    def _solve_reach(self) -> Reach:
        """Stations from the rest pose turned towards them; every other pose from the station
        it is reached from, so each move is short and stays in one IK branch."""
        top = self.layout.table_height
        hover = top + self.layout.hover_height
        low = top + GRASP_DEPTH
        targets: list[tuple[tuple[float, float, float], np.ndarray]] = []

        def solve(tip: tuple[float, float, float], start: np.ndarray) -> np.ndarray:
            q = self._solve(tip, start)
            targets.append((tip, q))
            return q

        station = {}
        for name in STATIONS:
            x, y = self.layout.station(name)
            rest = np.array(REST_POSE)
            rest[0] = math.atan2(y, x)
            station[name] = solve((x, y, hover), rest)
        grid_hover = tuple(solve((x, y, hover), station["center"]) for x, y in self.layout.grid())
        grid_low = tuple(
            solve((x, y, low), q) for (x, y), q in zip(self.layout.grid(), grid_hover, strict=True)
        )
        slot_hover = {
            s: tuple(solve((x, y, hover), station[s]) for x, y in self.layout.slots(s))
            for s in ("left", "right")
        }
        slot_low = {
            s: tuple(
                solve((x, y, low), q)
                for (x, y), q in zip(self.layout.slots(s), slot_hover[s], strict=True)
            )
            for s in ("left", "right")
        }
        for tip, q in targets:
            self.set_joints(q)
            error = float(np.linalg.norm(self.cup_tip() - tip))
            assert error < 0.01, f"IK misses {tip} by {error:.3f} m: the layout is out of reach"
        return Reach(station, grid_hover, grid_low, slot_hover, slot_low)

    def cup_tip(self) -> np.ndarray:
        state = self.p.getLinkState(self.body, CUP_LINK, computeForwardKinematics=True)
        return np.array(state[4]) - np.array([0.0, 0.0, CUP_LENGTH / 2])

    def joints(self) -> np.ndarray:
        return np.array([s[0] for s in self.p.getJointStates(self.body, range(JOINTS))])

    def set_joints(self, q: np.ndarray) -> None:
        """Teleport the joints (and hold them there under position control)."""
        for j in range(JOINTS):
            self.p.resetJointState(self.body, j, float(q[j]), 0.0)
        self._command(q)

    def _command(self, q: np.ndarray, velocity: np.ndarray | None = None) -> None:
        """Position control towards `q`, with `velocity` fed forward along a path."""
        self.p.setJointMotorControlArray(
            self.body, range(JOINTS), pybullet.POSITION_CONTROL, targetPositions=list(q),
            targetVelocities=list(np.zeros(JOINTS) if velocity is None else velocity),
            forces=[MOTOR_FORCE] * JOINTS, positionGains=[POSITION_GAIN] * JOINTS,
        )  # fmt: skip

    # -- actions ----------------------------------------------------------------------

    def reset(self) -> None:
        """Empty-handed above the center table."""
        if self.held is not None:
            self._release()
        self.station = "center"
        self.set_joints(self.reach.station["center"])

    def go_to(self, station: str) -> None:
        """To a station's hover pose, carrying whatever is held."""
        if self.physics:
            self._drive(self.reach.station[station])
        else:
            self.set_joints(self.reach.station[station])
            self._carry()
        self.station = station

    def grab(self, target: int, candidates: list[int]) -> int | None:
        """Pick `target` from the center table and come back above the table's middle.

        Returns the body picked: in physics, whichever of `candidates` the cup touched
        first, or None if it touched none before reaching the table.
        """
        assert self.held is None
        if not self.physics:
            self.set_joints(self.reach.station["center"])
            self.station = "center"
            self._attach_fast(target)
            return target
        (x, y, _), _ = self.p.getBasePositionAndOrientation(target)
        grid = np.array(self.layout.grid())
        k = int(np.argmin(np.linalg.norm(grid - (x, y), axis=1)))
        if np.linalg.norm(grid[k] - (x, y)) < 0.01:
            hover, low = self.reach.grid_hover[k], self.reach.grid_low[k]
        else:  # knocked aside: solve from where the arm is, without teleporting it
            top = self.layout.table_height
            hover = self._solve((x, y, top + self.layout.hover_height), None)
            low = self._solve((x, y, top + GRASP_DEPTH), None)
        self._drive(hover)
        touched: list[int] = []

        def contact() -> bool:
            touched.extend(
                c[2] for c in self.p.getContactPoints(bodyA=self.body, linkIndexA=CUP_LINK)
                if c[2] in candidates
            )  # fmt: skip
            return bool(touched)

        self._drive(low, stop=contact, speed=DESCENT_SPEED)
        if touched:
            self._attach_physics(touched[0])
        self._drive(hover)  # straight up first: a diagonal would sweep the neighbours away
        self._drive(self.reach.station["center"])
        self.station = "center"
        return self.held

    def drop(self, side: str, slot: int) -> int:
        """Lower the held object onto a slot of the side table the arm is at; returns it."""
        assert self.held is not None and self.station == side
        held = self.held
        top = self.layout.table_height
        if not self.physics:
            _, orientation = self.p.getBasePositionAndOrientation(held)
            x, y = self.layout.slots(side)[slot]
            self._release()
            z = top + self.half_heights[held]
            self.p.resetBasePositionAndOrientation(held, (x, y, z), orientation)
            return held
        self._drive(self.reach.slot_hover[side][slot])

        def low_enough() -> bool:
            return self.p.getAABB(held)[0][2] <= top + RELEASE_GAP

        self._drive(self.reach.slot_low[side][slot], stop=low_enough, speed=DESCENT_SPEED)
        self._release(keep_filter=True)
        for _ in range(6):
            self.world.step()
        self._drive(self.reach.slot_hover[side][slot])
        self._drive(self.reach.station[side])
        self._set_cup_collisions(held, enabled=True)
        return held

    # -- suction ----------------------------------------------------------------------

    def _attach_physics(self, body: int) -> None:
        # The cup's pose computed here, never PyBullet's cached link state: recording the
        # motion (or a viewer reading poses) refreshes that cache, and a grasp made from a
        # stale one would hold the object differently in an unrecorded run.
        cup_pos, cup_orn = self._cup_pose()
        pos, orn = self.p.getBasePositionAndOrientation(body)
        inv_pos, inv_orn = self.p.invertTransform(cup_pos, cup_orn)
        rel_pos, rel_orn = self.p.multiplyTransforms(inv_pos, inv_orn, pos, orn)
        self._set_cup_collisions(body, enabled=False)
        self._constraint = self.p.createConstraint(
            self.body, CUP_LINK, body, -1, pybullet.JOINT_FIXED, (0, 0, 0),
            rel_pos, (0, 0, 0), rel_orn, (0, 0, 0, 1),
        )  # fmt: skip
        self.p.changeConstraint(self._constraint, maxForce=200.0)
        self.held = body

    def _attach_fast(self, body: int) -> None:
        """The object hangs just under the cup, keeping its heading."""
        _, orn = self.p.getBasePositionAndOrientation(body)
        cup_pos, cup_orn = self._cup_pose()
        below = CUP_LENGTH / 2 + self.half_heights[body]
        inv_pos, inv_orn = self.p.invertTransform(cup_pos, cup_orn)
        world_pos = (cup_pos[0], cup_pos[1], cup_pos[2] - below)
        self._held_offset = self.p.multiplyTransforms(inv_pos, inv_orn, world_pos, orn)
        self.held = body
        self._carry()

    def _cup_pose(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        state = self.p.getLinkState(self.body, CUP_LINK, computeForwardKinematics=True)
        return state[4], state[5]

    def _carry(self) -> None:
        if self.held is None or self._held_offset is None:
            return
        pos, orn = self.p.multiplyTransforms(*self._cup_pose(), *self._held_offset)
        self.p.resetBasePositionAndOrientation(self.held, pos, orn)

    def _release(self, keep_filter: bool = False) -> None:
        assert self.held is not None
        if self._constraint is not None:
            self.p.removeConstraint(self._constraint)
            self._constraint = None
        if not keep_filter:
            self._set_cup_collisions(self.held, enabled=True)
        self.held = None
        self._held_offset = None

    def _set_cup_collisions(self, body: int, enabled: bool) -> None:
        """A held object must not collide with the cup it hangs from, nor the flange."""
        for link in (CUP_LINK, CUP_LINK - 1):
            self.p.setCollisionFilterPair(self.body, body, link, -1, int(enabled))

    # -- physics motion ---------------------------------------------------------------

    def _drive(
        self, goal: np.ndarray, stop: Callable[[], bool] | None = None, speed: float = 1.0
    ) -> None:
        """Track a smooth joint-space path to `goal` with position control.

        The path is a smoothstep, its peak joint speed `JOINT_SPEED * speed` (it lasts at
        least 0.06 s) and its velocity fed forward; then the arm settles within
        `SETTLE_TOLERANCE`. All of it fits in `MOVE_BUDGET` steps. `stop` ends the move
        early (the cup touched something).
        """
        start = self.joints()
        delta = goal - start
        duration = max(0.06, 1.5 * float(np.max(np.abs(delta))) / (JOINT_SPEED * speed))
        steps = min(MOVE_BUDGET, math.ceil(duration / TIME_STEP))
        for i in range(1, MOVE_BUDGET + 1):
            s = min(1.0, i / steps)
            rate = 6 * s * (1 - s) / (steps * TIME_STEP)  # d/dt of the smoothstep
            self._command(start + delta * (s * s * (3 - 2 * s)), delta * rate)
            self.world.step()
            if stop is not None and stop():
                self._command(self.joints())
                return
            if i >= steps and float(np.max(np.abs(self.joints() - goal))) < SETTLE_TOLERANCE:
                return
