"""Where everything stands: tables, the 3x3 grid, the objects' sizes, the camera.

The numbers are chosen together: objects large enough that a held one covers dozens of
pixels of the 64x64 image at every station, tables within the iiwa's comfortable reach,
and a camera that sees the arm, the held object and all three tables at once.
World frame: z up, the robot's base at the origin facing +x, its left is +y.
"""

from dataclasses import dataclass

from sim.bodies import Color

RED: Color = (0.85, 0.08, 0.06, 1.0)
BLUE: Color = (0.08, 0.22, 0.9, 1.0)
OBJECT_COLORS: dict[str, Color] = {"red": RED, "blue": BLUE}


@dataclass(frozen=True)
class Table:
    """A table: a box standing on the floor, its top at `Layout.table_height`."""

    name: str
    """Scene path, e.g. `tables/center`."""
    center: tuple[float, float]
    """x, y of the table's middle, metres."""
    half_size: tuple[float, float]
    """Half the top's size along x and y, metres."""
    rgba: Color
    """Colour."""


@dataclass(frozen=True)
class ObjectShape:
    """Size of one kind of object; all stand upright with their axis along z."""

    shape: str
    """`cube`, `cylinder` or `disk`."""
    radius: float
    """Half the width of a cube, or the radius of a cylinder or disk, metres."""
    half_height: float
    """Half the height, metres: how far the centre sits above the table when resting."""


@dataclass(frozen=True)
class CameraPose:
    """The fixed camera on the robot's table."""

    eye: tuple[float, float, float]
    """Camera position, metres."""
    target: tuple[float, float, float]
    """The point it looks at."""
    fov: float = 60.0
    """Vertical field of view, degrees."""
    near: float = 0.05
    """Near clipping distance, metres."""
    far: float = 4.0
    """Far clipping distance, metres."""


@dataclass(frozen=True)
class Layout:
    """The scene's geometry."""

    table_height: float = 0.40
    """Height of every table's top (and of the robot's base), metres."""
    robot_table: Table = Table(
        "tables/robot", (-0.15, -0.33), (0.25, 0.73), (0.55, 0.55, 0.55, 1.0)
    )
    """The bench the arm stands on (at the origin) and, at its right end, the camera."""
    center_table: Table = Table("tables/center", (0.6, 0.0), (0.24, 0.24), (0.93, 0.9, 0.82, 1.0))
    """Holds the unsorted objects on the 3x3 grid."""
    left_table: Table = Table("tables/left", (0.36, 0.48), (0.2, 0.18), (0.93, 0.9, 0.82, 1.0))
    """Receives the objects sorted left (+y)."""
    right_table: Table = Table("tables/right", (0.36, -0.48), (0.2, 0.18), (0.93, 0.9, 0.82, 1.0))
    """Receives the objects sorted right (-y)."""
    station_points: tuple[tuple[float, float], ...] = ((0.6, 0.0), (0.38, 0.38), (0.38, -0.38))
    """x, y of the cup at the center, left and right stations: the side stations are over the
    side tables' inner halves, close together so the camera sees each one large."""
    grid_spacing: float = 0.15
    """Distance between neighbouring grid positions on the center table, metres."""
    slot_spacing: tuple[float, float] = (0.14, 0.16)
    """Distance between the 3x2 drop slots of a side table along x and y, metres: wide
    enough that a dropped disk never touches its neighbours, all within the arm's reach."""
    objects: tuple[ObjectShape, ...] = (
        ObjectShape("cube", 0.05, 0.05),
        ObjectShape("cylinder", 0.045, 0.06),
        ObjectShape("disk", 0.065, 0.025),
    )
    """The three shapes, each in red and blue: toy-block sizes, so that a held one covers a
    few dozen of the camera's pixels wherever the arm is."""
    object_mass: float = 0.1
    """Kilograms, each object."""
    hover_height: float = 0.32
    """Height of the suction cup's tip above the tables at a station, metres: a held object
    clears the objects still on the center table."""
    floor_rgba: Color = (0.35, 0.37, 0.4, 1.0)
    """A plain floor: a textured plane would cost the camera about 1.5 ms a frame."""
    camera: CameraPose = CameraPose((-0.25, -0.95, 1.15), (0.45, 0.05, 0.62), fov=45.0)
    """The agent's camera, on a mast at the right end of the robot's bench, looking across
    the arm: from there no link hides the held object at any station."""

    def station(self, name: str) -> tuple[float, float]:
        """x, y of the cup at station `name` (`center`, `left` or `right`)."""
        return self.station_points[("center", "left", "right").index(name)]

    def grid(self) -> list[tuple[float, float]]:
        """The 9 positions (x, y) on the center table, row by row."""
        cx, cy = self.center_table.center
        d = self.grid_spacing
        return [(cx + i * d, cy + j * d) for i in (-1, 0, 1) for j in (-1, 0, 1)]

    def slots(self, side: str) -> list[tuple[float, float]]:
        """The 6 drop positions (x, y) on a side table, filled in this order: the row nearer
        the center table first, middle first."""
        cx, cy = self.side_table(side).center
        dx, dy = self.slot_spacing
        sign = 1.0 if cy > 0 else -1.0
        return [(cx + i * dx, cy + sign * j * dy / 2) for j in (-1, 1) for i in (0, -1, 1)]

    def side_table(self, side: str) -> Table:
        return self.left_table if side == "left" else self.right_table

    def tables(self) -> tuple[Table, ...]:
        return (self.robot_table, self.center_table, self.left_table, self.right_table)
