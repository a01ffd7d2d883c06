"""Mesh files a simulation loaded (`sim.MeshFile`: an URDF's OBJ or STL, from pybullet_data
or a task's own package), read from this machine's disk for the 3-D view.

The web process reads each file once (cached) and sends its triangles to the page over the
viewer's own websocket: nothing is fetched from elsewhere, and the page needs no loader of
its own. Plain NumPy and regular expressions, so the web process loads no mesh library.
"""

from __future__ import annotations

import functools
import itertools
import re
import struct
from pathlib import Path

import numpy as np

SUFFIXES = (".obj", ".stl")
_VERTEX = re.compile(r"^v\s+(\S+)\s+(\S+)\s+(\S+)", re.MULTILINE)
_FACE = re.compile(r"^f\s+(.+)$", re.MULTILINE)


class MeshFileError(ValueError):
    """A mesh the view cannot read; the message names the file."""


@functools.cache
def read_mesh(path: str) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (N, 3) float32 and triangles (M, 3) uint32 of an OBJ or STL file; cached, so
    the arrays are shared and read-only."""
    file = Path(path)
    if file.suffix.lower() not in SUFFIXES or not file.is_file():
        raise MeshFileError(f"{path}: the 3-D view reads .obj and .stl files on this machine")
    data = file.read_bytes()
    vertices, faces = _obj(data.decode()) if file.suffix.lower() == ".obj" else _stl(data)
    if len(faces) and (faces.max() >= len(vertices) or faces.min() < 0):
        raise MeshFileError(f"{path}: a face names a vertex the file does not have")
    vertices.flags.writeable = False
    faces.flags.writeable = False
    return vertices, faces


def scaled(path: str, scale: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    vertices, faces = read_mesh(path)
    return (vertices * np.asarray(scale, dtype=np.float32)).astype(np.float32), faces


def _obj(text: str) -> tuple[np.ndarray, np.ndarray]:
    """An OBJ's vertices and its faces, polygons split into fans (`v/vt/vn` read as `v`)."""
    vertices = np.array(_VERTEX.findall(text), dtype=np.float32).reshape(-1, 3)
    triangles: list[tuple[int, int, int]] = []
    for line in _FACE.findall(text):
        corners = [int(c.split("/")[0]) for c in line.split()]
        corners = [c - 1 if c > 0 else len(vertices) + c for c in corners]  # negative: relative
        triangles.extend((corners[0], b, c) for b, c in itertools.pairwise(corners[1:]))
    return vertices, np.array(triangles, dtype=np.int64).reshape(-1, 3).astype(np.uint32)


def _stl(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """A binary or ASCII STL's triangles, each with its own three vertices."""
    if len(data) >= 84:
        (count,) = struct.unpack_from("<I", data, 80)
        if len(data) == 84 + 50 * count:
            records = np.frombuffer(data, dtype=np.uint8, offset=84).reshape(count, 50)
            corners = records[:, 12:48].copy().view("<f4").reshape(-1, 3).astype(np.float32)
            return corners, np.arange(len(corners), dtype=np.uint32).reshape(-1, 3)
    text = data.decode(errors="replace")
    numbers = re.findall(r"vertex\s+(\S+)\s+(\S+)\s+(\S+)", text)
    corners = np.array(numbers, dtype=np.float32).reshape(-1, 3)
    corners = corners[: len(corners) // 3 * 3]
    return corners, np.arange(len(corners), dtype=np.uint32).reshape(-1, 3)
