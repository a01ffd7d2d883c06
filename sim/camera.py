"""The agent's eye: a fixed 64x64 RGB camera rendered by PyBullet's TinyRenderer.

TinyRenderer is software rendering: the same pixels on every machine, no display needed.
Shadows and the segmentation mask are off because each costs time per frame and the
agent needs neither.
"""

import numpy as np

from sim.bullet import pybullet
from sim.layout import CameraPose
from sim.world import World

IMAGE_SIZE = 64


class Camera:
    """Renders what the agent sees."""

    def __init__(
        self, world: World, pose: CameraPose, size: int = IMAGE_SIZE, height: int | None = None
    ) -> None:
        """`size` wide and `height` (default `size`) high; `pose.fov` is vertical."""
        self.world = world
        self.size = size
        self.height = height or size
        self.view = world.p.computeViewMatrix(pose.eye, pose.target, (0.0, 0.0, 1.0))
        self.projection = world.p.computeProjectionMatrixFOV(
            pose.fov, size / self.height, pose.near, pose.far
        )

    def _render(self, flags: int) -> tuple:
        return self.world.p.getCameraImage(
            self.size, self.height, self.view, self.projection,
            shadow=0, flags=flags, renderer=pybullet.ER_TINY_RENDERER,
        )  # fmt: skip

    def image(self) -> np.ndarray:
        """uint8 (size, size, 3)."""
        rgba = self._render(pybullet.ER_NO_SEGMENTATION_MASK)[2]
        return np.ascontiguousarray(
            np.asarray(rgba, dtype=np.uint8).reshape(self.height, self.size, 4)[:, :, :3]
        )

    def visible_pixels(self) -> dict[tuple[int, int], int]:
        """Pixels covered by each (body, link), link -1 for a base: a second render, with
        the segmentation mask, for checking what the agent can see."""
        flags = pybullet.ER_SEGMENTATION_MASK_OBJECT_AND_LINKINDEX
        mask = np.asarray(self._render(flags)[4]).reshape(-1)
        ids, counts = np.unique(mask[mask >= 0], return_counts=True)
        return {
            (int(i) & ((1 << 24) - 1), (int(i) >> 24) - 1): int(c)
            for i, c in zip(ids, counts, strict=True)
        }
