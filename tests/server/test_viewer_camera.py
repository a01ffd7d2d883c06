"""The participant's default 3-D view shows what the robot holds and what is left on the
center table, wherever the arm is: rendered from the real scene (PyBullet), counting the
pixels each body covers from the viewer's camera."""

from __future__ import annotations

import pytest

import sim
from server.viewer.camera import VIEWER_CAMERA, viser_camera_params
from sim.layout import CameraPose

SIZE = (320, 270)
"""About the 3-D pane's shape on a laptop screen, at a quarter of its pixels."""
MIN_HELD_PX = 150
MIN_OBJECT_PX = 8
"""An object covering fewer pixels than this is hidden (behind the arm, or another object)."""
OLD_CAMERA = CameraPose((-0.12, -0.5, 1.72), (0.42, 0.02, 0.4), fov=75.0)
"""The view before issue 10, whose arm hid the center table when at the right station."""


def _name(held: str) -> str:
    """The scene path of a held object, from sim's info ("shape/color")."""
    shape, color = held.split("/")
    return f"objects/{shape}_{color}"


def _hidden_and_held(camera: CameraPose, seed: int) -> tuple[list[str], list[int]]:
    env = sim.SortingEnv(motion="fast")
    try:
        _, info = env.reset(seed=seed)
        hidden: list[str] = []
        held_px: list[int] = []
        # grab (held at the center), carry right, carry left, back to the center
        for action in (None, sim.Action.GRAB, sim.Action.MOVE_RIGHT, sim.Action.MOVE_LEFT,
                       sim.Action.GRAB):  # fmt: skip
            if action is not None:
                _, _, _, _, info = env.step(action)
            pixels = env.unwrapped.visible_pixels(camera, SIZE)
            held = _name(info["held"]) if info["held"] else None
            if held is not None:
                held_px.append(pixels[held])
            where = f"{info['station']} holding {held}"
            hidden += [
                f"{_name(o)} ({where})"
                for o, on_center in zip(sim.OBJECTS, info["on_center"], strict=True)
                if on_center and _name(o) != held and pixels[_name(o)] < MIN_OBJECT_PX
            ]
        return hidden, held_px
    finally:
        env.close()


@pytest.mark.parametrize("seed", [3, 5, 11])
def test_the_default_view_shows_the_center_table_and_the_held_object(seed: int) -> None:
    hidden, held_px = _hidden_and_held(VIEWER_CAMERA, seed)
    assert not hidden, f"hidden from the participant's view: {hidden}"
    assert len(held_px) == 4 and min(held_px) >= MIN_HELD_PX, held_px


def test_the_old_view_hid_objects_behind_the_arm() -> None:
    """What the test above guards against happens with the view it replaced."""
    hidden = [h for seed in (3, 5, 11) for h in _hidden_and_held(OLD_CAMERA, seed)[0]]
    assert any("right holding" in h for h in hidden), hidden


def test_the_camera_reaches_viser_in_its_units() -> None:
    params = viser_camera_params()
    assert params["initialCameraPosition"] == "-0.5,-0.95,1.57"
    assert params["initialCameraUp"] == "0,0,1"
    assert float(params["initialCameraFov"]) == pytest.approx(0.8727, abs=1e-4)
