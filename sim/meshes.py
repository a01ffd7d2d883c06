"""The KUKA iiwa's meshes: read for the 3-D viewer, simplified for the camera.

PyBullet's TinyRenderer transforms every triangle of every body for each image, so the
iiwa's 13,000 visual triangles alone would cost about 4 ms a frame. At 64x64 pixels
(about 1.5 cm a pixel on the arm) the convex hull of 64 points of each link looks the same
with a twentieth of the triangles, so the arm PyBullet loads has such meshes, written to a
cache folder; the viewer still gets the full meshes from `read_obj`.
"""

import contextlib
import functools
import hashlib
import os
import re
import stat
import tempfile
from pathlib import Path

import numpy as np
import pybullet_data
from scipy.spatial import ConvexHull

IIWA_DIR = Path(pybullet_data.getDataPath()) / "kuka_iiwa"
ARM_LINKS = 8
"""Links of the iiwa with a mesh: `lbr_iiwa_link_0` (the base) to `lbr_iiwa_link_7`."""


_VERTEX = re.compile(r"^v\s+(\S+)\s+(\S+)\s+(\S+)", re.MULTILINE)
_TRIANGLE = re.compile(r"^f\s+(\d+)\S*\s+(\d+)\S*\s+(\d+)\S*\s*$", re.MULTILINE)
_FACE = re.compile(r"^f\s", re.MULTILINE)


@functools.cache
def read_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (N, 3) float64 and triangles (M, 3) int32 (0-based) of a triangulated OBJ.

    Cached, so the arrays are shared and read-only.
    """
    text = path.read_text()
    vertices = np.array(_VERTEX.findall(text), dtype=np.float64)
    faces = np.array(_TRIANGLE.findall(text), dtype=np.int32).reshape(-1, 3) - 1
    assert len(faces) == len(_FACE.findall(text)), f"{path} has faces that are not triangles"
    vertices.flags.writeable = False
    faces.flags.writeable = False
    return vertices, faces


def farthest_points(vertices: np.ndarray, count: int) -> np.ndarray:
    """`count` vertices spread over the shape: each the farthest from those already chosen."""
    chosen = [int(np.argmax(vertices[:, 2]))]
    distance = np.linalg.norm(vertices - vertices[chosen[0]], axis=1)
    for _ in range(count - 1):
        chosen.append(int(np.argmax(distance)))
        distance = np.minimum(distance, np.linalg.norm(vertices - vertices[chosen[-1]], axis=1))
    return vertices[chosen]


def simplify(vertices: np.ndarray, points: int) -> tuple[np.ndarray, np.ndarray]:
    """The convex hull of `points` well-spread vertices, triangles wound outwards.

    The iiwa's links are nearly convex, so at camera resolution the hull is the link.
    """
    hull = ConvexHull(farthest_points(vertices, points))
    used, faces = np.unique(hull.simplices, return_inverse=True)
    hull_vertices = hull.points[used]
    faces = faces.reshape(-1, 3)
    a, b, c = (hull_vertices[faces[:, i]] for i in range(3))
    inward = np.einsum("ij,ij->i", a - hull_vertices.mean(axis=0), np.cross(b - a, c - a)) < 0
    faces[inward] = faces[inward][:, ::-1]
    return hull_vertices, faces.astype(np.int32)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals, so TinyRenderer shades the simplified mesh smoothly."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    face_normals = np.cross(b - a, c - a)
    normals = np.zeros_like(vertices)
    for i in range(3):
        np.add.at(normals, faces[:, i], face_normals)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return normals / np.where(length > 0, length, 1.0)


def obj_text(vertices: np.ndarray, faces: np.ndarray) -> str:
    normals = vertex_normals(vertices, faces)
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    lines += [f"vn {x:.6f} {y:.6f} {z:.6f}" for x, y, z in normals]
    lines += [f"f {a}//{a} {b}//{b} {c}//{c}" for a, b, c in faces + 1]
    return "\n".join(lines) + "\n"


def link_mesh_path(link: int) -> Path:
    """The full-resolution visual mesh of `lbr_iiwa_link_{link}`, in that link's frame."""
    return IIWA_DIR / "meshes" / f"link_{link}.obj"


def model_folder() -> Path:
    """This user's folder for the generated model files: `ideeprl-sim-UID`, mode 0700.

    One folder per user, because a folder shared by every user holds files that only their
    first writer can read: once root has run the platform, a service running as its own user
    fails every session with "Cannot load URDF file". A folder of that name that is not this
    user's own directory, or that others may write to (and so may have changed the robot), is
    passed over for a new one.
    """
    base = Path(tempfile.gettempdir())
    folder = base / f"ideeprl-sim-{os.getuid()}"
    with contextlib.suppress(FileExistsError):
        folder.mkdir(mode=0o700)
    info = folder.lstat()
    if stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid() and not info.st_mode & 0o022:
        return folder
    return Path(tempfile.mkdtemp(prefix=f"{folder.name}-", dir=base))


def _write_once(path: Path, text: str) -> None:
    """Write atomically, so processes building environments side by side never see half a file."""
    if path.exists():
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.replace(tmp, path)


@functools.cache
def arm_urdf(
    cup_xml: str, link_rgba: tuple[tuple[float, float, float, float], ...], hull_points: int
) -> Path:
    """The iiwa URDF with simplified meshes, recoloured links and `cup_xml` appended.

    The simplified (convex) meshes serve for collisions too: PyBullet would take the convex
    hull of the stock meshes anyway, and loading 64-point hulls is five times faster, which
    matters because the physics mode rebuilds the world at every reset.

    Link colours are replaced because the stock orange and light blue would be confused with
    the red and blue objects in a 64x64 image. Files go to a folder in this user's
    `model_folder` named by a hash of their content, so changing any argument (or
    pybullet_data) makes a new, consistent set.
    """
    assert len(link_rgba) == ARM_LINKS
    meshes = {
        link: obj_text(*simplify(read_obj(link_mesh_path(link))[0], hull_points))
        for link in range(ARM_LINKS)
    }
    urdf = (IIWA_DIR / "model.urdf").read_text()
    digest = hashlib.sha256(
        "\n".join([urdf, cup_xml, repr(link_rgba), *meshes.values()]).encode()
    ).hexdigest()[:16]
    folder = model_folder() / digest
    for link, text in meshes.items():
        _write_once(folder / f"link_{link}.obj", text)

    urdf = re.sub(r"meshes/(link_\d)\.(obj|stl)", lambda m: str(folder / f"{m.group(1)}.obj"), urdf)
    for link, rgba in enumerate(link_rgba):
        color = " ".join(f"{c:g}" for c in rgba)
        urdf = re.sub(
            rf'(<link name="lbr_iiwa_link_{link}">.*?<visual>.*?)<material name="\w+"/>',
            rf'\1<material name="link_{link}"><color rgba="{color}"/></material>',
            urdf,
            count=1,
            flags=re.DOTALL,
        )
    urdf = urdf.replace("</robot>", cup_xml + "\n</robot>")
    path = folder / "iiwa_suction.urdf"
    _write_once(path, urdf)
    return path
