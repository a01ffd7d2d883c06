"""Pictures for people: what the agent sees, and the scene seen from outside.

    python -m sim.pictures docs/images

writes `observations.png` (the 64x64 camera image, 4x enlarged, at each station with
nothing, a red object or a blue object held: the nine images the agent must tell apart)
and `scene.png` (the room from its two far corners, mid-episode, in the physics mode).
"""

import argparse
import itertools
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from sim.actions import Action
from sim.camera import Camera
from sim.env import SortingEnv
from sim.layout import CameraPose
from sim.rules import oracle_action

SCALE = 4
MARGIN = 28
STATION_MOVES = {"center": [], "left": [Action.MOVE_LEFT], "right": [Action.MOVE_RIGHT]}


def first_grab_seed(env: SortingEnv, color: str) -> int:
    """A seed whose first grab picks an object of `color` (grab picks at random)."""
    for seed in range(100):
        env.reset(seed=seed)
        if env.step(Action.GRAB)[4]["held_color"] == color:
            return seed
    raise RuntimeError(f"no seed below 100 grabs a {color} object first")


def observations(env: SortingEnv) -> Image.Image:
    """The nine observations in a labelled grid: rows held nothing/red/blue, columns the
    stations."""
    size = 64 * SCALE
    grid = Image.new("RGB", (MARGIN + 3 * size, MARGIN + 3 * size), "white")
    draw = ImageDraw.Draw(grid)
    seeds = {color: first_grab_seed(env, color) for color in ("red", "blue")}
    rows, columns = ("nothing", "red", "blue"), tuple(STATION_MOVES)
    for (i, held), (j, station) in itertools.product(enumerate(rows), enumerate(columns)):
        obs, _ = env.reset(seed=seeds.get(held, 0))
        for action in ([] if held == "nothing" else [Action.GRAB]) + STATION_MOVES[station]:
            obs = env.step(action)[0]
        tile = Image.fromarray(obs).resize((size, size), Image.Resampling.NEAREST)
        grid.paste(tile, (MARGIN + j * size, MARGIN + i * size))
        draw.text((MARGIN + j * size + size // 2 - 20, 8), f"at {station}", fill="black")
        draw.text((4, MARGIN + i * size + size // 2), held, fill="black")
    return grid


def scene(env: SortingEnv) -> Image.Image:
    """The room from the two far corners, after two objects are sorted and a third is held."""
    _, info = env.reset(seed=0)
    for _ in range(7):
        info = env.step(oracle_action(info, "color"))[4]
    views = [
        Camera(env._world, CameraPose((1.9, y, 1.7), (0.25, y / 10, 0.5), 42.0), 400).image()
        for y in (-1.5, 1.5)
    ]
    return Image.fromarray(np.concatenate(views, axis=1))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description="Draw the pictures of the scenario.")
    parser.add_argument("folder", type=Path, help="where to write the PNG files")
    folder = parser.parse_args(argv).folder
    folder.mkdir(parents=True, exist_ok=True)
    fast, physics = SortingEnv(motion="fast"), SortingEnv(motion="physics")
    observations(fast).save(folder / "observations.png")
    scene(physics).save(folder / "scene.png")
    fast.close()
    physics.close()
    print(f"wrote {folder / 'observations.png'} and {folder / 'scene.png'}")


if __name__ == "__main__":
    main()
