"""The physics mode: the arm really moves, picks by suction and objects can be knocked off."""

import numpy as np
import pytest

import sim
from tests.sim.conftest import run_oracle

GRAB, RIGHT, LEFT, DROP = sim.Action


def on_table(env: sim.SortingEnv, name: str, table: str) -> bool:
    layout = env.layout
    t = {"left": layout.left_table, "right": layout.right_table, "center": layout.center_table}
    x, y, z = env.body_poses()[name].position
    (cx, cy), (hx, hy) = t[table].center, t[table].half_size
    return abs(x - cx) < hx and abs(y - cy) < hy and layout.table_height < z < 0.6


def test_oracle_sorts_onto_the_right_tables(physics_env: sim.SortingEnv) -> None:
    total, steps, terminated, truncated, _info = run_oracle(physics_env, seed=0)
    assert (total, steps, terminated, truncated) == (3.0, 18, True, False)
    for shape in sim.SHAPES:
        assert on_table(physics_env, f"objects/{shape}_red", "left")
        assert on_table(physics_env, f"objects/{shape}_blue", "right")


@pytest.mark.slow
def test_oracle_succeeds_on_almost_every_seed(physics_env: sim.SortingEnv) -> None:
    results = [run_oracle(physics_env, seed) for seed in range(20)]
    good = [seed for seed, r in enumerate(results) if r[0] >= 2.6]
    assert len(good) >= 18, [(seed, r[0], r[1]) for seed, r in enumerate(results)]
    assert max(r[1] for r in results) <= 30


def test_the_held_object_hangs_from_the_cup_wherever_the_arm_goes(
    physics_env: sim.SortingEnv,
) -> None:
    _, info = physics_env.reset(seed=1)
    _, _, _, _, info = physics_env.step(GRAB)
    name = f"objects/{info['held'].replace('/', '_')}"
    for action in (LEFT, RIGHT, GRAB):
        _, _, _, _, info = physics_env.step(action)
        poses = physics_env.body_poses()
        cup, held = np.array(poses["arm/suction_cup"].position), np.array(poses[name].position)
        assert np.linalg.norm(cup[:2] - held[:2]) < 0.03, info["station"]
        assert 0.05 < cup[2] - held[2] < 0.15
        station = np.array(physics_env.layout.station(info["station"]))
        assert np.linalg.norm(cup[:2] - station) < 0.02


def test_an_object_knocked_off_the_table_is_lost_without_reward(
    physics_env: sim.SortingEnv,
) -> None:
    _, info = physics_env.reset(seed=2)
    victim = int(np.flatnonzero(info["on_center"])[0])
    name = f"objects/{sim.OBJECTS[victim].replace('/', '_')}"
    # Knock it just past the table's far edge (as a careless arm would), then let the arm
    # move: the object falls while the world steps.
    world, body = physics_env._world, physics_env._objects[name].body
    table = physics_env.layout.center_table
    edge = table.center[0] + table.half_size[0] + 0.1
    world.p.resetBasePositionAndOrientation(body, (edge, 0.0, 0.5), (0.0, 0.0, 0.0, 1.0))
    _, reward, terminated, _, info = physics_env.step(LEFT)
    assert (reward, terminated, info["lost"]) == (0.0, False, 1)
    assert not info["on_center"][victim] and info["remaining"] == 5
    assert physics_env.body_poses()[name].position[2] < physics_env.layout.table_height
    # The other five, sorted, complete the task: 4 x 0.4 + 1.0.
    total, steps = 0.0, 1
    while True:
        _, reward, terminated, truncated, info = physics_env.step(sim.oracle_action(info, "color"))
        total, steps = total + reward, steps + 1
        if terminated or truncated:
            break
    assert info["is_success"] and info["placed_correct"] == 5
    assert total == pytest.approx(2.6) and steps == 16


def test_objects_pushed_aside_on_the_table_are_still_picked(physics_env: sim.SortingEnv) -> None:
    _, info = physics_env.reset(seed=4)
    world = physics_env._world
    for obj in physics_env._objects.values():  # all 3 cm towards the robot: off the grid
        (x, y, z), orientation = world.p.getBasePositionAndOrientation(obj.body)
        world.p.resetBasePositionAndOrientation(obj.body, (x - 0.03, y, z), orientation)
    for placed in range(3):
        _, _, _, _, info = physics_env.step(GRAB)
        assert info["held"] != "" and info["remaining"] == 5 - placed
        physics_env.step(sim.oracle_action(info, "color"))
        _, reward, _, _, info = physics_env.step(DROP)
        assert (reward, info["lost"]) == (0.4, 0)
