"""What a viewer needs to mirror the scene without importing PyBullet.

A viewer calls `scene_bodies()` once per episode for the shapes, then `body_poses()` (or
replays `last_motion`) for where they are. Every geometry is given in its body's own
frame, the frame whose pose `body_poses()` reports.
"""

from dataclasses import dataclass

import numpy as np

Color = tuple[float, float, float, float]
"""RGBA, each in [0, 1]."""


@dataclass(frozen=True)
class Pose:
    """Where a body is, in the world frame (z up, metres)."""

    position: tuple[float, float, float]
    """x, y, z in metres."""
    orientation: tuple[float, float, float, float]
    """Unit quaternion in `w, x, y, z` order (viser's and most viewers'; PyBullet's is xyzw)."""


@dataclass(frozen=True)
class Box:
    """A box centred on its frame's origin."""

    half_extents: np.ndarray
    """Half the size along x, y, z, metres, shape (3,)."""


@dataclass(frozen=True)
class Cylinder:
    """A cylinder centred on its frame's origin, its axis along the frame's z."""

    radius: float
    """Metres."""
    length: float
    """Full length along z, metres."""


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh in its frame's coordinates."""

    vertices: np.ndarray
    """Positions, metres, float64 of shape (N, 3)."""
    faces: np.ndarray
    """Vertex indices (0-based) of each triangle, counter-clockwise seen from outside,
    int32 of shape (M, 3)."""


@dataclass(frozen=True)
class Sphere:
    """A sphere centred on its frame's origin."""

    radius: float
    """Metres."""


@dataclass(frozen=True)
class MeshFile:
    """A mesh the simulation loaded from a file (an URDF's OBJ or STL), named rather than
    sent: the viewer reads the file from this machine's disk once, and scales it."""

    path: str
    """Absolute path of the file, as PyBullet reports it."""
    scale: tuple[float, float, float]
    """Scale along the frame's x, y, z (the URDF's `scale`)."""


Geometry = Box | Cylinder | Sphere | Mesh | MeshFile
"""Every shape a body can have."""


@dataclass(frozen=True)
class BodySpec:
    """One body of the scene: its name, shape and colour (fixed for the whole scene)."""

    name: str
    """A stable scene path, e.g. `tables/center`, `objects/cube_red`, `arm/link_3`,
    `arm/suction_cup`; the key of this body in `body_poses()`."""
    geometry: Geometry
    """The shape, in the body's frame."""
    rgba: Color
    """Colour as the camera sees it."""
    moving: bool
    """Whether the body can move during an episode (arm links and objects); only moving
    bodies appear in `MotionFrame.poses`."""


@dataclass(frozen=True)
class MotionFrame:
    """The moving bodies at one instant of a step's motion, for smooth playback."""

    time: float
    """Simulated seconds since the start of the step's motion."""
    poses: dict[str, Pose]
    """Pose of every moving body, by `BodySpec.name`."""
