"""What the agent sees: the image alone must tell station and held object (SPEC 1)."""

import itertools

import numpy as np
import pytest

import sim
from tests.sim.conftest import clearly_different, seed_whose_first_grab_is

GRAB, RIGHT, LEFT, DROP = sim.Action
TO_STATION = {"center": [], "left": [LEFT], "right": [RIGHT]}
MIN_DIFFERENT_PIXELS = 20
"""Two images are clearly different when at least this many pixels differ by more than 30
levels (of 255) in some channel."""


def nine_observations(env: sim.SortingEnv) -> dict[tuple[str, str], np.ndarray]:
    """The image at each station with nothing, a red object or a blue object held."""
    seeds = {color: seed_whose_first_grab_is(env, color) for color in ("red", "blue")}
    images = {}
    for held, station in itertools.product(("nothing", "red", "blue"), TO_STATION):
        obs, _ = env.reset(seed=seeds.get(held, 0))
        actions = ([] if held == "nothing" else [GRAB]) + TO_STATION[station]
        for action in actions:
            obs, _, _, _, info = env.step(action)
        assert info["station"] == station if actions else True
        images[station, held] = obs
    return images


@pytest.mark.parametrize("motion", ["fast", "physics"])
def test_every_station_and_held_color_looks_clearly_different(motion: str) -> None:
    env = sim.SortingEnv(motion=motion)
    try:
        images = nine_observations(env)
    finally:
        env.close()
    for (a, image_a), (b, image_b) in itertools.combinations(images.items(), 2):
        assert clearly_different(image_a, image_b) >= MIN_DIFFERENT_PIXELS, (a, b)


def test_every_held_object_is_plainly_visible_at_every_station(fast_env: sim.SortingEnv) -> None:
    """Unoccluded pixels of the held object itself, from the camera's segmentation."""
    first_grab = {}
    for seed in range(200):
        fast_env.reset(seed=seed)
        info = fast_env.step(GRAB)[4]
        first_grab.setdefault(f"objects/{info['held_shape']}_{info['held_color']}", seed)
        if len(first_grab) == 6:
            break
    assert len(first_grab) == 6
    for name, seed in first_grab.items():
        for station, moves in TO_STATION.items():
            fast_env.reset(seed=seed)
            for action in [GRAB, *moves]:
                fast_env.step(action)
            assert fast_env.visible_pixels()[name] >= 20, (name, station)


def test_different_scenes_give_different_images(fast_env: sim.SortingEnv) -> None:
    first, _ = fast_env.reset(seed=0)
    assert any(
        clearly_different(first, fast_env.reset(seed=seed)[0]) >= MIN_DIFFERENT_PIXELS
        for seed in range(1, 4)
    )
