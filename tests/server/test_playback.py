"""The player's idea of when a view is done: the page keeps its buttons off, and the tests
read the scene, only once it is."""

from __future__ import annotations

import threading
import time
from typing import Any

import sim
from runs.worker.messages import SceneReset
from server.viewer.playback import Player


class SlowBuild:
    """The part of a scene the player drives, building as slowly as a loaded machine."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.building = threading.Event()
        self.built = threading.Event()

    def build(self, bodies: list[sim.BodySpec]) -> None:
        self.building.set()
        time.sleep(self.seconds)
        self.built.set()

    def apply(self, poses: Any) -> int:
        return 0


def test_a_view_building_its_scene_is_not_idle_however_long_it_takes() -> None:
    mirror = SlowBuild(seconds=0.5)
    player = Player(mirror, tick_hz=30.0).start()  # type: ignore[arg-type]
    try:
        player.push(SceneReset(bodies=[], poses={}, episode=-1))
        assert mirror.building.wait(5)
        readings = []
        while not mirror.built.is_set():
            readings.append(player.idle())
            time.sleep(0.01)
        assert len(readings) > 10 and not any(readings), "idle while the scene was half built"
        deadline = time.monotonic() + 5
        while not player.idle():
            assert time.monotonic() < deadline, "never idle once built"
            time.sleep(0.01)
    finally:
        player.close()
        player.join(5)
