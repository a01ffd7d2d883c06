"""The scene of one viser client: the simulation's bodies as client-scoped viser nodes.

Bodies are built once per scene (`sim.BodySpec`: boxes, cylinders, spheres, meshes given
or named by their files, in their colours) under their stable names as scene paths
(`/tables/left`, `/arm/link_3`), and then only moved. Nothing goes into viser's shared
scene, so a client without a session sees nothing.

Seen at an angle, an arm over a side table can look as if it were over the center table.
Two markers that are not part of the simulation settle it: a plumb line straight down from
the suction cup, and a spot where that line meets the tables' height (where a drop would
land); each table carries its name in large letters.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import viser

import sim
from server.viewer import meshes
from sim.layout import Layout

POSITION_EPS = 1e-5
"""Metres: a body that moved less than this is not sent again."""
SHADOWS = False
"""Shadows cost a second render pass; browsers without a GPU (software WebGL) then lag."""
SKY_RGB, GROUND_RGB, HEMISPHERE_INTENSITY = (255, 255, 255), (140, 140, 150), 2.6
"""The scene's light besides viser's default directional lights: a hemisphere light, white
from above and grey from below, in place of viser's image-based environment map. The map
makes every pixel sample a prefiltered HDR image: on a browser without a GPU (software
WebGL) an advice page waiting for advice keeps 0.77 of a core busy with it, 0.24 without
(AVX2-only EPYC, benchmarks/logs/idle-page-2026-12-04-avx2.log), for a look that hardly
differs (docs/screenshots). The same light for every participant, with a GPU or without:
what they see does not depend on their device."""
LABELS = {
    "tables/left": ("LEFT table", (0.0, 1.0)),
    "tables/right": ("RIGHT table", (0.0, -1.0)),
    "tables/center": ("CENTER table", (1.0, 0.0)),
}
"""Names shown above the tables, so a participant knows which is which from any angle; each
at the table's edge away from the arm (x, y in half extents), clear of the objects."""
LABEL_SCALE = 1.5
"""Label text at 1.5 times viser's default size: readable at a glance on a phone."""
MARKER_RGB = (255, 140, 0)
CUP = "arm/suction_cup"
PLUMB_LENGTH = 0.32
"""Metres: from the cup at its hover height down to the tables' tops (sim.layout)."""
TABLE_TOP = Layout().table_height


def _rgb(rgba: tuple[float, float, float, float]) -> tuple[int, int, int]:
    return (round(rgba[0] * 255), round(rgba[1] * 255), round(rgba[2] * 255))


def _opacity(rgba: tuple[float, float, float, float]) -> float | None:
    return None if rgba[3] >= 1.0 else float(rgba[3])


def light(scene: viser.SceneApi) -> None:
    """Light a client's scene (see `HEMISPHERE_INTENSITY`); no shadows (`SHADOWS`)."""
    scene.configure_environment_map(None)
    scene.configure_default_lights(enabled=True, cast_shadow=SHADOWS)
    scene.add_light_hemisphere(
        "/light/hemisphere",
        sky_color=SKY_RGB,
        ground_color=GROUND_RGB,
        intensity=HEMISPHERE_INTENSITY,
    )


def add_body(scene: viser.SceneApi, body: sim.BodySpec) -> Any:
    """One body as a viser node at the world origin (its pose is set afterwards)."""
    name, geometry = f"/{body.name}", body.geometry
    color, opacity = _rgb(body.rgba), _opacity(body.rgba)
    if isinstance(geometry, sim.Box):
        return scene.add_box(
            name,
            color=color,
            dimensions=_sizes(geometry.half_extents),
            opacity=opacity,
            cast_shadow=SHADOWS,
            receive_shadow=SHADOWS,
        )
    if isinstance(geometry, sim.Cylinder):
        return scene.add_cylinder(
            name,
            radius=float(geometry.radius),
            height=float(geometry.length),
            color=color,
            opacity=opacity,
            cast_shadow=SHADOWS,
            receive_shadow=SHADOWS,
        )
    if isinstance(geometry, sim.Sphere):
        return scene.add_icosphere(
            name,
            radius=float(geometry.radius),
            color=color,
            opacity=opacity,
            cast_shadow=SHADOWS,
            receive_shadow=SHADOWS,
        )
    if isinstance(geometry, sim.MeshFile):
        vertices, faces = meshes.scaled(geometry.path, geometry.scale)
    else:
        assert isinstance(geometry, sim.Mesh), f"unknown geometry {type(geometry).__name__}"
        vertices = np.asarray(geometry.vertices, dtype=np.float32)
        faces = np.asarray(geometry.faces, dtype=np.uint32)
    return scene.add_mesh_simple(
        name,
        vertices,
        faces,
        color=color,
        opacity=opacity,
        flat_shading=False,
        cast_shadow=SHADOWS,
        receive_shadow=SHADOWS,
    )


class SceneMirror:
    """The bodies of one client's scene, by name; `apply` moves them."""

    def __init__(self, client: viser.ClientHandle) -> None:
        self.client = client
        light(client.scene)
        self.handles: dict[str, Any] = {}
        self._sent: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {}
        self._names: tuple[str, ...] = ()
        self.markers: dict[str, Any] = {}
        """The plumb line and the spot under the cup (not simulated bodies)."""

    def build(self, bodies: list[sim.BodySpec]) -> None:
        """Create the bodies; a scene with the same bodies is kept as it is."""
        names = tuple(body.name for body in bodies)
        if names == self._names:
            return
        for handle in [*self.handles.values(), *self.markers.values()]:
            handle.remove()
        # Readers (`positions`, the tests) see no scene or the whole new one, never half of one.
        self.handles, self.markers, self._sent = {}, {}, {}
        handles: dict[str, Any] = {}
        with self.client.atomic():
            for body in bodies:
                handles[body.name] = add_body(self.client.scene, body)
                if body.name in LABELS and isinstance(body.geometry, sim.Box):
                    text, (fx, fy) = LABELS[body.name]
                    hx, hy, hz = (float(h) for h in body.geometry.half_extents)
                    self.client.scene.add_label(
                        f"/{body.name}/label",
                        text,
                        position=(fx * hx, fy * hy, hz + 0.03),
                        font_screen_scale=LABEL_SCALE,
                        anchor="bottom-center",
                    )
            markers = self._add_markers() if CUP in names else {}
        self.handles, self.markers = handles, markers
        self._names = names

    def _add_markers(self) -> dict[str, Any]:
        scene = self.client.scene
        plumb = scene.add_cylinder(
            "/markers/plumb",
            radius=0.004,
            height=PLUMB_LENGTH,
            color=MARKER_RGB,
            cast_shadow=False,
            receive_shadow=False,
        )
        spot = scene.add_cylinder(
            "/markers/spot",
            radius=0.055,
            height=0.004,
            color=MARKER_RGB,
            opacity=0.85,
            cast_shadow=False,
            receive_shadow=False,
        )
        return {"plumb": plumb, "spot": spot}

    def _move_markers(self, cup: tuple[float, ...]) -> None:
        x, y, z = cup
        self.markers["plumb"].position = (x, y, z - PLUMB_LENGTH / 2)
        self.markers["spot"].position = (x, y, TABLE_TOP + 0.003)

    def apply(self, poses: Mapping[str, sim.Pose]) -> int:
        """Move the bodies to `poses` in one atomic update; returns how many moved."""
        moved = 0
        with self.client.atomic():
            for name, pose in poses.items():
                handle = self.handles.get(name)
                if handle is None:
                    continue
                position = tuple(float(x) for x in pose.position)
                wxyz = tuple(float(x) for x in pose.orientation)
                last = self._sent.get(name)
                if last is not None and _close(last[0], position) and _close(last[1], wxyz):
                    continue
                handle.position = position
                handle.wxyz = wxyz
                self._sent[name] = (position, wxyz)
                moved += 1
                if name == CUP and self.markers:
                    self._move_markers(position)
        return moved

    def positions(self) -> dict[str, np.ndarray]:
        """Where each body's node is now (what this client is shown), in metres."""
        return {name: np.asarray(h.position, dtype=float) for name, h in self.handles.items()}

    def orientations(self) -> dict[str, np.ndarray]:
        return {name: np.asarray(h.wxyz, dtype=float) for name, h in self.handles.items()}


def _close(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    return max(abs(x - y) for x, y in zip(a, b, strict=True)) < POSITION_EPS


def _sizes(half_extents: np.ndarray) -> tuple[float, float, float]:
    """A box's full sizes from PyBullet's half extents."""
    x, y, z = (float(h) * 2 for h in half_extents)
    return x, y, z
