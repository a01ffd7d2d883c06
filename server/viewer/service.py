"""The participant's 3-D view: one viser server in the web process, one private scene per
participant.

The participant page embeds viser's client with its websocket at `/p/TOKEN`. When a
websocket opens, the token is checked against the database; a connection without a valid
token is closed before anything is sent to it. A valid one becomes a `ClientView` once
viser knows the client (after its first camera message): it subscribes to its session's
scene events on the hub and a `Player` draws them into the client's own scene. The hub
replays the latest scene to a new subscriber, so a reload or reconnect shows the scene
where it is at once.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass

import viser
from sqlalchemy.orm import Session, sessionmaker

from server.live.hub import Hub, HubEvent, Subscription
from server.viewer import connection
from server.viewer.mirror import SceneMirror
from server.viewer.playback import Player
from study.services.sessions import session_for_token
from study.settings import Settings

log = logging.getLogger(__name__)
SCENE_KINDS = ("scene_reset", "scene_step")


@dataclass(frozen=True)
class ViewerConfig:
    """Where the view listens and how it plays; the server fills it from its settings."""

    host: str = "127.0.0.1"
    """Interface the viser server listens on."""
    port: int = 8080
    """Its port; 0 picks a free one, and a taken one is skipped upwards (see `port`)."""
    playback_speed: float = 1.0
    """1 plays the robot's motion in real time; tests play it faster."""
    tick_hz: float = 30.0
    """Pose updates a second while the robot moves."""


class ClientView:
    """One participant's browser tab: its scene, its player, its hub subscription."""

    def __init__(self, client: viser.ClientHandle, session_id: int, config: ViewerConfig) -> None:
        self.client = client
        self.session_id = session_id
        self.mirror = SceneMirror(client)
        self.player = Player(self.mirror, config.playback_speed, config.tick_hz)
        self.subscription: Subscription | None = None
        self._replaying = False
        self._closed = False
        self._lock = threading.Lock()

    def open(self, hub: Hub) -> None:
        self.player.start()
        with self._lock:
            if self._closed:
                return
            self._replaying = True
            try:
                # The hub replays the latest scene now, on this thread: shown without motion.
                self.subscription = hub.subscribe(self.session_id, self._on_event, SCENE_KINDS)
            finally:
                self._replaying = False

    def _on_event(self, event: HubEvent) -> None:
        self.player.push(event.payload, instant=self._replaying)

    def close(self) -> None:
        with self._lock:
            self._closed = True
            if self.subscription is not None:
                self.subscription.close()
        self.player.close()


class ParticipantViewer:
    """The viser server and the participants' views, by viser client id."""

    def __init__(
        self, config: ViewerConfig, hub: Hub, session_for_token: Callable[[str], int | None]
    ) -> None:
        """`session_for_token(token)` is the session id a participant token reaches, or
        None; it may query the database (it runs on a worker thread)."""
        self.config = config
        self.hub = hub
        self._session_for_token = session_for_token
        self.server: viser.ViserServer | None = None
        self._lock = threading.Lock()
        self._admitted: dict[int, int] = {}
        self._views: dict[int, ClientView] = {}
        self.refused = 0
        """Websockets closed for want of a valid token (since start)."""

    # --- lifecycle ---------------------------------------------------------------------
    def start(self) -> None:
        server = connection.guarded_server(
            self.config.host, self.config.port, self._admit, self._forget, self._connected
        )
        self.server = server

    def stop(self) -> None:
        with self._lock:
            views = list(self._views.values())
            self._views.clear()
            self._admitted.clear()
        for view in views:
            view.close()
        if self.server is not None:
            self.server.stop()
            self.server = None

    @property
    def port(self) -> int:
        """The port viser actually listens on."""
        assert self.server is not None, "the viewer has not started"
        return int(self.server.get_port())

    # --- who may connect -----------------------------------------------------------------
    async def _admit(self, client_id: int) -> None:
        assert self.server is not None
        session_id = await connection.admitted(
            self.server,
            client_id,
            self._session_for_token,
            self._refused,
            "no valid participant token",
        )
        if session_id is not None:
            with self._lock:
                self._admitted[client_id] = session_id

    def _refused(self) -> None:
        with self._lock:
            self.refused += 1

    def _connected(self, client: viser.ClientHandle) -> None:
        with self._lock:
            session_id = self._admitted.get(client.client_id)
        if session_id is None:
            return  # refused, or gone already
        view = ClientView(client, session_id, self.config)
        with self._lock:
            if client.client_id not in self._admitted:
                return
            self._views[client.client_id] = view
        view.open(self.hub)

    def _forget(self, client_id: int) -> None:
        with self._lock:
            self._admitted.pop(client_id, None)
            view = self._views.pop(client_id, None)
        if view is not None:
            view.close()

    # --- what the pages and tests ask ------------------------------------------------------
    def views(self, session_id: int | None = None) -> list[ClientView]:
        with self._lock:
            return [v for v in self._views.values() if session_id in (None, v.session_id)]

    def scene_shown(self, session_id: int) -> bool:
        """Whether a view of the session has its scene's bodies: viser's client has drawn
        (it knows a client after its first camera message) and has the scene to draw."""
        return any(v.mirror.handles for v in self.views(session_id))

    def playback_remaining_s(self, session_id: int) -> float:
        """Real seconds until every view of the session has shown all it received."""
        return max((v.player.remaining_s() for v in self.views(session_id)), default=0.0)


def token_lookup(factory: sessionmaker[Session]) -> Callable[[str], int | None]:
    """Participant token -> session id, from the database."""

    def lookup(token: str) -> int | None:
        with factory() as db:
            session = session_for_token(db, token)
            return session.id if session is not None else None

    return lookup


def viewer_from_settings(
    settings: Settings, hub: Hub, factory: sessionmaker[Session]
) -> ParticipantViewer:
    config = ViewerConfig(
        host=settings.viser_host,
        port=settings.viser_port,
        playback_speed=settings.viewer_playback_speed,
    )
    return ParticipantViewer(config, hub, token_lookup(factory))
