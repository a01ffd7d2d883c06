"""A PyBullet capsule in the 3-D view: a closed mesh with its round ends, where PyBullet has
the capsule (not a flat-ended cylinder)."""

from __future__ import annotations

import numpy as np
import pytest

import sim
from sim.bullet import pybullet
from sim.visuals import BulletScene, capsule
from sim.world import Client


def test_a_capsule_is_a_closed_outward_mesh_of_its_size() -> None:
    radius, length = 0.05, 0.3
    mesh = capsule(radius, length)
    edges = [(int(f[i]), int(f[(i + 1) % 3])) for f in mesh.faces for i in range(3)]
    assert len(set(edges)) == len(edges), "each directed edge once: the faces agree in turn"
    assert set(edges) == {(b, a) for a, b in edges}, "every edge between two faces: closed"
    # The divergence theorem: the signed volume is positive only if the faces face outward.
    a, b, c = (mesh.vertices[mesh.faces[:, i]] for i in range(3))
    volume = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6)
    exact = np.pi * radius**2 * length + 4 / 3 * np.pi * radius**3
    assert volume == pytest.approx(exact, rel=0.05)
    axis = np.clip(mesh.vertices[:, 2], -length / 2, length / 2)
    off_axis = np.linalg.norm(mesh.vertices - np.stack([0 * axis, 0 * axis, axis], 1), axis=1)
    assert np.allclose(off_axis, radius), "every point at the radius from the axis segment"
    assert mesh.vertices[:, 2].max() == pytest.approx(length / 2 + radius)
    assert mesh.vertices[:, 2].min() == pytest.approx(-length / 2 - radius)


def test_a_pybullet_capsule_becomes_the_capsules_mesh() -> None:
    p = Client()
    try:
        shape = p.createVisualShape(pybullet.GEOM_CAPSULE, radius=0.04, length=0.2)
        body = p.createMultiBody(baseMass=0, baseVisualShapeIndex=shape)
        scene = BulletScene(p, {"rod": body})
        (spec,) = scene.specs
        assert isinstance(spec.geometry, sim.Mesh)
        heights = spec.geometry.vertices[:, 2]
        assert heights.max() == pytest.approx(0.1 + 0.04)
        assert np.linalg.norm(spec.geometry.vertices[:, :2], axis=1).max() == pytest.approx(0.04)
    finally:
        p.disconnect()
