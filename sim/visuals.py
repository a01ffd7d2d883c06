"""Any PyBullet scene as the viewer's bodies, read from PyBullet itself.

A task names the bodies people should see (`{"arm": arm_id, "goal": goal_id}`); each visual
shape of each of their links becomes one `BodySpec` (boxes, spheres, cylinders, capsules as
closed meshes with their round ends, and meshes named by their files), in the colours
PyBullet draws them, and `poses()` says where each shape is now. A shape's pose is its
link's frame (the URDF's, not the centre of mass that PyBullet reports for a base) composed
with the shape's own local frame, so a viewer only places each shape, with no knowledge of
links or joints.

A task whose camera renders simplified meshes (TinyRenderer's time grows with triangles)
names the full ones people should see instead (`shown_meshes`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from sim.bodies import BodySpec, Box, Cylinder, Geometry, Mesh, MeshFile, Pose, Sphere
from sim.bullet import pybullet
from sim.world import Client, wxyz

CAPSULE_SEGMENTS = 24
"""Points around a capsule's axis; its round ends have a quarter as many rings each."""
PLANE_HALF_SIZE = 5.0
"""Metres: an infinite plane is shown as a square this far from its origin each way."""
Frame = tuple[tuple[float, float, float], tuple[float, float, float, float]]
"""A position and a quaternion in PyBullet's (x, y, z, w) order."""


@dataclass(frozen=True)
class Shape:
    """One visual shape: which body and link carries it, and where on that link."""

    name: str
    body: int
    link: int
    """-1 for the base."""
    local: Frame
    """The shape's frame in its link's frame."""


def geometry(kind: int, dimensions: Iterable[float], mesh: bytes) -> Geometry | None:
    """A visual shape's geometry from `getVisualShapeData`'s fields, or None for a kind a
    viewer cannot draw."""
    d = [float(x) for x in dimensions]
    if kind == pybullet.GEOM_BOX:
        return Box(np.asarray(d[:3]) / 2)  # PyBullet reports a box's full sizes
    if kind == pybullet.GEOM_SPHERE:
        return Sphere(d[0])
    if kind == pybullet.GEOM_CYLINDER:
        return Cylinder(radius=d[1], length=d[0])
    if kind == pybullet.GEOM_CAPSULE:
        return capsule(radius=d[1], length=d[0])
    if kind == pybullet.GEOM_MESH:
        path = mesh.decode()
        return MeshFile(path, (d[0], d[1], d[2])) if path else None
    if kind == pybullet.GEOM_PLANE:
        return Box(np.array([PLANE_HALF_SIZE, PLANE_HALF_SIZE, 0.0005]))
    return None


def capsule(radius: float, length: float, segments: int = CAPSULE_SEGMENTS) -> Mesh:
    """A capsule as a closed triangle mesh: a cylinder of `length` along z between two
    half-spheres of `radius` (PyBullet's capsule: its length excludes the round ends)."""
    rings = max(2, segments // 4)
    # Latitudes from the top pole to the bottom one; the equator is repeated, once for each
    # end, the cylinder's wall being the band between the two.
    latitudes = np.linspace(np.pi / 2, 0.0, rings + 1)[1:]
    heights = [(np.sin(a) * radius + length / 2, np.cos(a) * radius) for a in latitudes]
    heights += [(-z, r) for z, r in reversed(heights)]
    around = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring_points = [
        np.stack([r * np.cos(around), r * np.sin(around), np.full(segments, z)], axis=1)
        for z, r in heights
    ]
    top, bottom = len(heights) * segments, len(heights) * segments + 1
    vertices = np.concatenate(
        [*ring_points, [[0.0, 0.0, length / 2 + radius], [0.0, 0.0, -length / 2 - radius]]]
    )
    faces: list[tuple[int, int, int]] = []
    for j in range(segments):
        k = (j + 1) % segments
        faces.append((top, j, k))  # the top cap, seen from outside (counter-clockwise)
        last = (len(heights) - 1) * segments
        faces.append((bottom, last + k, last + j))
        for ring in range(len(heights) - 1):
            a, b = ring * segments, (ring + 1) * segments
            faces += [(a + j, b + j, b + k), (a + j, b + k, a + k)]
    return Mesh(vertices, np.asarray(faces, dtype=np.int32))


class BulletScene:
    """The visual shapes of named PyBullet bodies, read once; their poses on demand."""

    def __init__(
        self,
        p: Client,
        bodies: Mapping[str, int],
        still: Iterable[str] = (),
        shown_meshes: Mapping[str, str] | None = None,
    ) -> None:
        """`bodies`: a scene name for each body; `still`: those that never move;
        `shown_meshes`: the file people see for a mesh file PyBullet loaded, where another."""
        self.p = p
        self.shapes: list[Shape] = []
        self.specs: list[BodySpec] = []
        still = set(still)
        for name, body in bodies.items():
            links = self._link_names(body)
            data = p.getVisualShapeData(body)
            per_link: dict[int, int] = {}
            for entry in data:
                per_link[entry[1]] = per_link.get(entry[1], 0) + 1
            seen: dict[int, int] = {}
            for entry in data:
                link, kind, dims, mesh, pos, orn, rgba = entry[1:8]
                shape = geometry(kind, dims, mesh)
                if isinstance(shape, MeshFile) and shape.path in (shown_meshes or {}):
                    shape = MeshFile((shown_meshes or {})[shape.path], shape.scale)
                if shape is None:
                    continue
                path = name if len(links) == 1 else f"{name}/{links[link]}"
                if per_link[link] > 1:
                    path = f"{path}/{seen.setdefault(link, 0)}"
                    seen[link] += 1
                self.shapes.append(Shape(path, body, link, (tuple(pos), tuple(orn))))
                colour = (float(rgba[0]), float(rgba[1]), float(rgba[2]), float(rgba[3]))
                self.specs.append(BodySpec(path, shape, colour, moving=name not in still))

    def _link_names(self, body: int) -> dict[int, str]:
        """Each link's URDF name by index, the base's at -1."""
        names = {-1: self.p.getBodyInfo(body)[0].decode() or "base"}
        for joint in range(self.p.getNumJoints(body)):
            names[joint] = self.p.getJointInfo(body, joint)[12].decode()
        return names

    def link_frames(self) -> dict[tuple[int, int], Frame]:
        """Each (body, link)'s frame in the world, the URDF's own."""
        frames: dict[tuple[int, int], Frame] = {}
        for body in {s.body for s in self.shapes}:
            position, orientation = self.p.getBasePositionAndOrientation(body)
            inertial = self.p.getDynamicsInfo(body, -1)[3:5]
            inverse = self.p.invertTransform(*inertial)
            frames[(body, -1)] = self.p.multiplyTransforms(position, orientation, *inverse)
            links = sorted({s.link for s in self.shapes if s.body == body and s.link >= 0})
            if links:
                states = self.p.getLinkStates(body, links, computeForwardKinematics=True)
                for link, state in zip(links, states, strict=True):
                    frames[(body, link)] = (tuple(state[4]), tuple(state[5]))
        return frames

    def poses(self) -> dict[str, Pose]:
        """Where each shape is now, by name."""
        frames = self.link_frames()
        poses: dict[str, Pose] = {}
        for shape in self.shapes:
            position, orientation = self.p.multiplyTransforms(
                *frames[(shape.body, shape.link)], *shape.local
            )
            poses[shape.name] = Pose(
                (float(position[0]), float(position[1]), float(position[2])), wxyz(orientation)
            )
        return poses
