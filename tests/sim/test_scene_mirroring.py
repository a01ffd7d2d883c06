"""What a viewer needs to mirror the scene: bodies, poses, and the motion of each step."""

import numpy as np
import pytest

import sim

GRAB, RIGHT, LEFT, DROP = sim.Action


def test_scene_bodies_name_every_body_with_its_shape(fast_env: sim.SortingEnv) -> None:
    specs = {spec.name: spec for spec in fast_env.scene_bodies()}
    expected = {"floor", "tables/robot", "tables/center", "tables/left", "tables/right"}
    expected |= {f"objects/{s}_{c}" for s in sim.SHAPES for c in sim.COLORS}
    expected |= {f"arm/link_{i}" for i in range(8)} | {"arm/suction_cup"}
    assert expected <= set(specs)
    assert isinstance(specs["tables/center"].geometry, sim.Box)
    assert isinstance(specs["objects/cylinder_red"].geometry, sim.Cylinder)
    assert specs["objects/cube_blue"].rgba[2] > 0.8 > specs["objects/cube_blue"].rgba[0]
    for i in range(8):
        mesh = specs[f"arm/link_{i}"].geometry
        assert isinstance(mesh, sim.Mesh) and mesh.vertices.shape[1] == 3
        assert mesh.faces.shape[1] == 3 and mesh.faces.dtype == np.int32
        assert mesh.faces.min() >= 0 and mesh.faces.max() < len(mesh.vertices)
        assert len(mesh.faces) > 1000  # the full iiwa meshes, not the camera's hulls
    moving = {name for name, spec in specs.items() if spec.moving}
    assert moving == {n for n in expected if n.startswith(("objects/", "arm/"))} - {"arm/link_0"}


def test_body_poses_follow_the_scene(fast_env: sim.SortingEnv) -> None:
    _, info = fast_env.reset(seed=0)
    poses = fast_env.body_poses()
    assert set(poses) == {spec.name for spec in fast_env.scene_bodies()}
    for pose in poses.values():
        assert np.linalg.norm(pose.orientation) == pytest.approx(1.0)
    grid = np.array(fast_env.layout.grid())
    for kind in np.array(sim.OBJECTS)[np.array(info["on_center"])]:
        x, y, z = poses[f"objects/{kind.replace('/', '_')}"].position
        assert np.min(np.linalg.norm(grid - (x, y), axis=1)) < 1e-6
        assert z > fast_env.layout.table_height
    # The base's mesh frame is where the arm stands, not PyBullet's centre of mass.
    assert poses["arm/link_0"].position == (0.0, 0.0, fast_env.layout.table_height)
    cup_before = poses["arm/suction_cup"].position
    fast_env.step(LEFT)
    cup_after = fast_env.body_poses()["arm/suction_cup"].position
    assert cup_after[1] - cup_before[1] > 0.3  # left is +y


def test_physics_motion_is_recorded_densely_enough_to_replay() -> None:
    env = sim.SortingEnv(motion="physics", record_motion=True)
    try:
        env.reset(seed=3)
        assert len(env.last_motion) == 1
        _, _, _, _, info = env.step(GRAB)
        frames = env.last_motion
        moving = {spec.name for spec in env.scene_bodies() if spec.moving}
        times = [frame.time for frame in frames]
        assert times[0] == 0.0 and times == sorted(times) and times[-1] > 0.3
        assert max(np.diff(times)) <= 1 / 20 + 1e-9
        assert all(set(frame.poses) == moving for frame in frames)
        assert frames[-1].poses == {name: env.body_poses()[name] for name in moving}
        cup_z = [frame.poses["arm/suction_cup"].position[2] for frame in frames]
        assert min(cup_z) < cup_z[0] - 0.15  # it went down to the object and came back
        assert abs(cup_z[-1] - cup_z[0]) < 0.01
        env.step(RIGHT if info["held_color"] == "red" else LEFT)  # wrong way: fine
        env.step(RIGHT if info["held_color"] == "red" else LEFT)  # already there
        assert len(env.last_motion) == 1
    finally:
        env.close()


def test_fast_motion_gives_a_frame_before_and_after_a_move() -> None:
    env = sim.SortingEnv(motion="fast", record_motion=True)
    try:
        env.reset(seed=3)
        before = env.body_poses()["arm/suction_cup"]
        env.step(LEFT)
        first, last = env.last_motion
        assert first.poses["arm/suction_cup"] == before
        assert last.poses["arm/suction_cup"] == env.body_poses()["arm/suction_cup"]
        assert last.time > first.time == 0.0
    finally:
        env.close()
