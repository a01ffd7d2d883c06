"""The room: floor, tables, the six objects, and where the objects start.

Objects are dynamic bodies in both motion modes; only the physics mode ever steps them.
"""

import math
from dataclasses import dataclass

import numpy as np

from sim.bodies import Box, Pose
from sim.layout import OBJECT_COLORS, Layout, Table
from sim.rules import COLORS
from sim.world import Part, World, wxyz


@dataclass(frozen=True)
class SceneObject:
    """One of the six objects."""

    name: str
    """Scene path, `objects/{shape}_{color}`."""
    shape: str
    """`cube`, `cylinder` or `disk`."""
    color: str
    """`red` or `blue`."""
    body: int
    """PyBullet body id."""
    half_height: float
    """Centre height above a table it rests on, metres."""


class Scene:
    """Builds the static room and the objects, and places the objects at reset."""

    def __init__(self, world: World, layout: Layout) -> None:
        self.world = world
        self.layout = layout
        top = layout.table_height
        world.add_box("floor", (4.0, 4.0, 0.01), (0.3, 0.0, -0.01), layout.floor_rgba)
        for table in layout.tables():
            hx, hy = table.half_size
            world.add_box(table.name, (hx, hy, top / 2), (*table.center, top / 2), table.rgba)
        self._add_camera_props()
        self.objects: list[SceneObject] = []
        self._parking: dict[int, tuple[float, float, float]] = {}
        for i, kind in enumerate(layout.objects):
            for j, color in enumerate(COLORS):
                name = f"objects/{kind.shape}_{color}"
                park = (-1.0 - 0.2 * i, 0.2 * j, kind.half_height)
                rgba = OBJECT_COLORS[color]
                mass = layout.object_mass
                if kind.shape == "cube":
                    half = (kind.radius, kind.radius, kind.half_height)
                    body = world.add_box(name, half, park, rgba, mass=mass)
                else:
                    body = world.add_cylinder(
                        name, kind.radius, 2 * kind.half_height, park, rgba, mass
                    )
                self.objects.append(SceneObject(name, kind.shape, color, body, kind.half_height))
                self._parking[body] = park
        self.by_body = {obj.body: obj for obj in self.objects}

    def _add_camera_props(self) -> None:
        """The camera and its mast, for the viewer only: PyBullet's camera needs no body."""
        eye, target = self.layout.camera.eye, self.layout.camera.target
        top = self.layout.table_height
        mast_height = eye[2] - top
        identity = (1.0, 0.0, 0.0, 0.0)
        dx, dy, dz = (t - e for t, e in zip(target, eye, strict=True))
        pitch, yaw = math.atan2(-dz, math.hypot(dx, dy)), math.atan2(dy, dx)
        facing = wxyz(self.world.p.getQuaternionFromEuler((0.0, pitch, yaw)))
        self.world.add_part(
            "camera/mast",
            Part(-1, -1, Pose((eye[0], eye[1], top + mast_height / 2), identity)),
            Box(np.array([0.012, 0.012, mast_height / 2])),
            (0.2, 0.2, 0.2, 1.0),
            moving=False,
        )
        self.world.add_part(
            "camera/body",
            Part(-1, -1, Pose(eye, facing)),  # its x axis looks at the target
            Box(np.array([0.05, 0.04, 0.035])),
            (0.1, 0.1, 0.1, 1.0),
            moving=False,
        )

    def place_objects(self, rng: np.random.Generator) -> None:
        """The six objects on 6 of the 9 grid positions, at random, upright and at rest."""
        grid = self.layout.grid()
        positions = rng.permutation(len(grid))[: len(self.objects)]
        top = self.layout.table_height
        for obj, k in zip(self.objects, positions, strict=True):
            x, y = grid[int(k)]
            self.world.p.resetBasePositionAndOrientation(
                obj.body, (x, y, top + obj.half_height), (0.0, 0.0, 0.0, 1.0)
            )
            self.world.p.resetBaseVelocity(obj.body, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))

    def knock_off(self, obj: SceneObject) -> None:
        """Take an object off the center table, as the authors' scene did with objects the
        arm knocked down (`Simulador.py:144-156`): it goes back to where it waits unused."""
        self.world.p.resetBasePositionAndOrientation(
            obj.body, self._parking[obj.body], (0.0, 0.0, 0.0, 1.0)
        )
        self.world.p.resetBaseVelocity(obj.body, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))

    def is_on(self, obj: SceneObject, table: Table) -> bool:
        """Whether the object's centre is above `table`'s top, within its edges."""
        (x, y, z), _ = self.world.p.getBasePositionAndOrientation(obj.body)
        cx, cy = table.center
        hx, hy = table.half_size
        return abs(x - cx) <= hx and abs(y - cy) <= hy and z > self.layout.table_height
