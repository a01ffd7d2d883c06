"""What the tests read from the participant's 3-D view: server-side (the viser handles of
each client's scene) and in the browser (the pixels of viser's canvas)."""

from __future__ import annotations

import io
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
from PIL import Image

from server.viewer import ClientView
from tests.e2e.conftest import Live


def views(live: Live, session_id: int) -> list[ClientView]:
    return live.app.state.viewer.views(session_id)


def wait_for_scene(live: Live, session_id: int, timeout: float = 120) -> ClientView:
    """The session's one open view, once it has built the scene's bodies."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = [v for v in views(live, session_id) if len(v.mirror.handles) >= 20]
        if found:
            assert len(found) == 1, f"{len(found)} views of session {session_id}"
            return found[0]
        time.sleep(0.1)
    raise AssertionError(f"no 3-D view of session {session_id} drew the scene")


def wait_idle(live: Live, session_id: int, timeout: float = 60) -> None:
    deadline = time.monotonic() + timeout
    while live.app.state.viewer.playback_remaining_s(session_id) > 0:
        assert time.monotonic() < deadline, "the 3-D view kept playing"
        time.sleep(0.05)


def distances(view: ClientView, poses: Mapping[str, Any]) -> dict[str, float]:
    """Metres between each body in the client's scene and the given pose."""
    shown = view.mirror.positions()
    return {
        name: float(np.linalg.norm(shown[name] - np.asarray(pose.position)))
        for name, pose in poses.items()
    }


def canvas_pixels(page: Any) -> np.ndarray:
    """The middle of the 3-D view as the participant sees it (RGB)."""
    png = page.locator("#scene").screenshot(timeout=120_000, animations="disabled")
    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=float)
    h, w, _ = image.shape
    return image[h // 4 : 3 * h // 4, w // 4 : 3 * w // 4]


def colored(pixels: np.ndarray) -> dict[str, int]:
    """How many pixels look like the red and the blue objects."""
    r, g, b = pixels[..., 0], pixels[..., 1], pixels[..., 2]
    return {
        "red": int(((r > 150) & (g < 110) & (b < 110)).sum()),
        "blue": int(((b > 150) & (r < 130) & (g < 130)).sum()),
    }
