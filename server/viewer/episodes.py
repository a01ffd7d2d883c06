"""The 3-D view of the dashboard's playbacks: a viser server of its own, apart from the
participants' (`service.py`), started when the first playback is opened.

A playback page embeds viser's client with its websocket at `/viewer/playback/ID`, relayed
to this server's `/p/ID`; a websocket whose id is no open playback is closed before
anything is sent to it. The page says which step it shows (`show`), and each of the
playback's views draws the scene at that step's decision: the poses before its action,
the moment the learner's 64x64 image shows; the index after the last step is the
episode's end. One step forward plays the previous step's motion, as the live view would
have; any other jump is drawn at once.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass

import viser

from runs.worker.messages import SceneStep
from runs.worker.rerun import Rerun
from server.viewer import connection
from server.viewer.mirror import SceneMirror
from server.viewer.playback import Player


@dataclass
class _View:
    mirror: SceneMirror
    player: Player
    playback_id: str
    shown: int | None = None
    """The step index (0-based) whose decision the view shows; None before the scene."""


class PlaybackViewer:
    """The viser server and the playbacks' views."""

    def __init__(
        self,
        host: str,
        speed: float,
        rerun_of: Callable[[str], Rerun | None],
        exists: Callable[[str], bool],
    ) -> None:
        """`rerun_of(id)`: the playback's rerun when it is ready; `exists(id)`: whether a
        playback with this id is open (its websocket may connect before the rerun ends)."""
        self.host = host
        self.speed = speed
        self._rerun_of = rerun_of
        self._exists = exists
        self.server: viser.ViserServer | None = None
        self._lock = threading.Lock()
        self._admitted: dict[int, str] = {}
        self._views: dict[int, _View] = {}
        self._current: dict[str, int] = {}
        self._drawing = threading.Lock()
        self.refused = 0

    # --- lifecycle ---------------------------------------------------------------------
    def ensure_started(self) -> None:
        with self._lock:
            if self.server is not None:
                return
            server = connection.guarded_server(
                self.host, 0, self._admit, self._forget, self._connected
            )
            self.server = server

    def stop(self) -> None:
        with self._lock:
            views = list(self._views.values())
            self._views.clear()
            self._admitted.clear()
            server, self.server = self.server, None
        for view in views:
            view.player.close()
        if server is not None:
            server.stop()

    @property
    def port(self) -> int | None:
        server = self.server
        return int(server.get_port()) if server is not None else None

    # --- who may connect -----------------------------------------------------------------
    async def _admit(self, client_id: int) -> None:
        assert self.server is not None
        playback_id = await connection.admitted(
            self.server, client_id, self._known, self._refused, "no open playback"
        )
        if playback_id is not None:
            with self._lock:
                self._admitted[client_id] = playback_id

    def _refused(self) -> None:
        with self._lock:
            self.refused += 1

    def _known(self, playback_id: str) -> str | None:
        return playback_id if self._exists(playback_id) else None

    def _connected(self, client: viser.ClientHandle) -> None:
        with self._lock:
            playback_id = self._admitted.get(client.client_id)
            if playback_id is None:
                return
            mirror = SceneMirror(client)
            view = _View(mirror, Player(mirror, self.speed), playback_id)
            self._views[client.client_id] = view
            current = self._current.get(playback_id)
        view.player.start()
        if current is not None:
            self._draw(view, current)

    def _forget(self, client_id: int) -> None:
        with self._lock:
            self._admitted.pop(client_id, None)
            view = self._views.pop(client_id, None)
        if view is not None:
            view.player.close()

    # --- what the routes ask ---------------------------------------------------------------
    def show(self, playback_id: str, index: int) -> int:
        """Every view of the playback draws step `index`'s decision; returns how many."""
        with self._lock:
            self._current[playback_id] = index
            views = [v for v in self._views.values() if v.playback_id == playback_id]
        for view in views:
            self._draw(view, index)
        return len(views)

    def close(self, playback_id: str) -> None:
        """The playback ended: its views stop drawing (the page learns it from the API)."""
        with self._lock:
            self._current.pop(playback_id, None)
            gone = [cid for cid, v in self._views.items() if v.playback_id == playback_id]
        for client_id in gone:
            self._forget(client_id)

    def views(self, playback_id: str) -> list[_View]:
        with self._lock:
            return [v for v in self._views.values() if v.playback_id == playback_id]

    def remaining_s(self, playback_id: str) -> float:
        """Real seconds until the playback's views have drawn what they were sent."""
        return max((v.player.remaining_s() for v in self.views(playback_id)), default=0.0)

    def _draw(self, view: _View, index: int) -> None:
        rerun = self._rerun_of(view.playback_id)
        if rerun is None or not 0 <= index <= len(rerun.steps):
            return
        with self._drawing:  # the routes' threads and viser's
            self._draw_locked(view, index, rerun)

    @staticmethod
    def _draw_locked(view: _View, index: int, rerun: Rerun) -> None:
        if view.shown is None:
            view.player.push(rerun.start, instant=True)
            view.shown = 0
        if index == view.shown + 1:
            view.player.push(rerun.steps[view.shown].scene)
        elif index != view.shown:
            poses = rerun.start.poses if index == 0 else rerun.steps[index - 1].scene.poses
            still = SceneStep(action=-1, reward=0.0, frames=[], poses=poses, global_step=index)
            view.player.push(still, instant=True)
        view.shown = index
