"""The 3-D view of a PyBullet task built from the simulation's own bodies (the reach task's
iiwa, floor and ball): one viser node for each visual shape PyBullet has, of its kind, with
the URDF's own mesh, and after the arm moves each node where PyBullet has its shape.

The nodes are real viser handles, in a viser server's scene (what a client's scene is
built with); where each shape is comes from PyBullet's own bounding boxes, computed apart
from the view's poses."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
import viser
from scipy.spatial.transform import Rotation

from server.viewer import meshes
from server.viewer.mirror import SceneMirror
from sim.bullet import pybullet
from sim.meshes import link_mesh_path
from tasks import get_task
from tasks.reach.env import ReachEnv

KIND = {pybullet.GEOM_MESH: "MeshHandle", pybullet.GEOM_SPHERE: "IcosphereHandle",
        pybullet.GEOM_BOX: "BoxHandle"}  # fmt: skip
"""The viser node each kind of PyBullet visual shape becomes."""


@pytest.fixture(scope="module")
def server() -> Iterator[viser.ViserServer]:
    made = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield made
    made.stop()


@pytest.fixture
def env() -> Iterator[ReachEnv]:
    made = get_task("reach").env({}, 250, True)
    yield made.unwrapped
    made.close()


def world_box(handle: object) -> np.ndarray:
    """The corners of a mesh node's own bounding box, where the page draws the node: what
    PyBullet's bounding box of a link holds too (its local box, turned and moved)."""
    vertices = np.asarray(handle.vertices)  # type: ignore[attr-defined]
    low, high = vertices.min(0), vertices.max(0)
    corners = np.array([[(low, high)[i >> k & 1][k] for k in range(3)] for i in range(8)])
    w, x, y, z = handle.wxyz  # type: ignore[attr-defined]
    moved = Rotation.from_quat([x, y, z, w]).apply(corners) + np.asarray(handle.position)  # type: ignore[attr-defined]
    return moved


def test_the_views_nodes_are_pybullets_visual_shapes_and_follow_them(
    server: viser.ViserServer, env: ReachEnv
) -> None:
    env.reset(seed=4)
    env.hand = (2, 3, 2)  # the lattice's middle: every move below moves the arm
    env._place_arm()
    mirror = SceneMirror(server)  # type: ignore[arg-type]  # a server's scene is a client's
    mirror.build(env.scene_bodies())
    mirror.apply(env.body_poses())
    p = env.p
    shapes = [s for body in range(p.getNumBodies()) for s in p.getVisualShapeData(body)]
    assert len(mirror.handles) == len(shapes) == 10  # floor, the iiwa's 8 links, ball
    kinds = sorted(type(h).__name__ for h in mirror.handles.values())
    assert kinds == sorted(KIND[s[2]] for s in shapes)
    for shape in shapes:  # the camera's hulls in PyBullet, the URDF's own meshes shown
        if shape[2] == pybullet.GEOM_MESH:
            handle = mirror.handles[f"arm/lbr_iiwa_link_{shape[1] + 1}"]
            vertices, faces = meshes.read_mesh(str(link_mesh_path(shape[1] + 1)))
            assert len(handle.vertices) == len(vertices) and len(faces) > 1000
            assert len(meshes.read_mesh(shape[4].decode())[1]) < len(faces) / 5

    for action in (0, 4, 2, 2, 5):  # the arm moves; the view is told only the new poses
        env.step(action)
        assert mirror.apply(env.body_poses()) >= 2
        for link in range(7):  # each link's mesh lies where PyBullet's own box says
            low, high = (np.asarray(c) for c in p.getAABB(env.arm, link))
            points = world_box(mirror.handles[f"arm/lbr_iiwa_link_{link + 1}"])
            assert np.abs(points.min(0) - low).max() < 0.03, link
            assert np.abs(points.max(0) - high).max() < 0.03, link
        ball = mirror.positions()["ball"]
        assert np.allclose(ball, p.getBasePositionAndOrientation(env.ball)[0], atol=1e-6)
    assert np.allclose(mirror.positions()["arm/lbr_iiwa_link_0"], 0.0, atol=1e-6)
    hand = mirror.positions()["arm/lbr_iiwa_link_7"]
    assert np.allclose(hand, env.hand_position(), atol=1e-6)


def test_a_mesh_file_the_view_cannot_read_is_named(tmp_path) -> None:
    with pytest.raises(meshes.MeshFileError, match=r"notes\.txt"):
        meshes.read_mesh(str(tmp_path / "notes.txt"))
    square = tmp_path / "square.obj"
    square.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1/1/1 2/2/1 3/3/1 4/4/1\n")
    vertices, faces = meshes.read_mesh(str(square))
    assert vertices.shape == (4, 3) and faces.tolist() == [[0, 1, 2], [0, 2, 3]]
