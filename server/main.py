"""The FastAPI app: `create_app(settings)`; `uvicorn --factory server.main:app_from_env
--ws-per-message-deflate false` (see `UVICORN_OPTIONS`)."""

from __future__ import annotations

import os
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException as StarletteHTTPException

from analysis.formats import figure_formats
from learner.fields import FieldError, leaves
from learner.run import declared
from runs.worker.rerun import Rerun
from runs.worker.worker import WorkerOptions
from server.deps import credential_guards
from server.guard import (
    LOGIN,
    Describe,
    Home,
    RequestGuard,
    SecurityHeaders,
    validation_error,
    without_input,
)
from server.limits import WindowLimit
from server.live import rating
from server.live.cluster import TrainingCluster, cluster_refusal
from server.live.hub import Hub
from server.live.manager import SessionManager
from server.live.playbacks import Playbacks
from server.live.pool import Pools
from server.logins import Logins
from server.openapi import install as install_openapi
from server.openapi import operation_id, path_methods
from server.routes import (
    ROUTERS,
    dashboard,
    joining,
    pages,
    playback,
    reports,
    sessions,
    viewing,
)
from server.routes.docs import add_docs
from server.viewer import proxy as viewer_proxy
from server.viewer import viewer_from_settings
from server.viewer.episodes import PlaybackViewer
from study.db.engine import make_engine, make_session_factory
from study.db.migrate import BACKUPS, upgrade
from study.services.errors import Invalid, ServiceError
from study.settings import Settings

API_VERSION = "2.0.0"
"""The REST API's version (the OpenAPI document's `info.version`): 2.0 carries a session's
run as one object, `run` (docs/api.md, "Changes")."""
UVICORN_OPTIONS: dict[str, Any] = {"ws_per_message_deflate": False}
"""How uvicorn must run this app: its only websocket is the 3-D view's relay, whose stream of
pose updates viser itself sends uncompressed ("compression can be too slow"); deflating it
again in the web process would cost that process the CPU its participants' requests need."""


class StartRefused(Exception):
    """The server cannot start as it is set up (the message says why): a Ray cluster it
    cannot store distributed work for, or figure formats it does not write."""


def worker_options(settings: Settings) -> WorkerOptions:
    """With a Ray cluster, checkpoints go to the storage root that every node sees."""
    return WorkerOptions(
        data_dir=settings.checkpoint_root,
        shared_storage=settings.shared_root is not None,
        checkpoint_every_episodes=settings.checkpoint_every_episodes,
        flush_every_steps=settings.flush_every_steps,
        heartbeat_s=settings.heartbeat_s,
        idle_limit_s=settings.idle_limit_s,
        nice=settings.trainer_nice,
        idle=settings.trainer_idle,
        keep_replay_memory=settings.keep_replay_memory,
    )


def describe_run_field() -> Describe:
    """What a field of a session body's `run` allows, by its path (for the guard's 422 on
    NaN and infinities, which it refuses before the body is validated)."""
    by_path = {leaf.path: leaf for leaf in leaves(declared())}

    def describe(path: tuple[str | int, ...]) -> str | None:
        leaf = by_path.get(tuple(map(str, path[1:]))) if path[:1] == ("run",) else None
        return leaf.allowed() if leaf is not None else None

    return describe


def run_field_home() -> Home:
    """Where a run's field of a given name belongs (`run.config.advice_budget`), for the
    422 on an unknown field: a run's field sent beside its `run` or in the wrong group."""
    places: dict[str, list[str]] = {}
    for leaf in leaves(declared()):
        places.setdefault(leaf.path[-1], []).append(".".join(("run", *leaf.path)))
    # a name that two groups share has no one home: it is named without one
    homes = {name: where[0] for name, where in places.items() if len(where) == 1}
    return homes.get


def episode_playback(settings: Settings) -> tuple[Playbacks, PlaybackViewer]:
    """The dashboard's playbacks and their 3-D view, each closing the other's part."""

    def rerun_of(playback_id: str) -> Rerun | None:
        playback = playbacks.get(playback_id, touch=False)
        return playback.rerun if playback is not None else None

    def exists(playback_id: str) -> bool:
        return playbacks.get(playback_id, touch=False) is not None

    viewer = PlaybackViewer(settings.viser_host, settings.viewer_playback_speed, rerun_of, exists)
    playbacks = Playbacks(
        settings.playback_limit, settings.playback_idle_s, lambda p: viewer.close(p.id)
    )
    return playbacks, viewer


def create_app(settings: Settings | None = None) -> FastAPI:
    """The web app. The body that creates a session, its schema and the exports are made
    from the run's declaration in force when it is created (`learner.run.declared`)."""
    settings = settings or Settings()
    try:  # checked here, not when a researcher's report is first drawn
        figure_formats()
    except ValueError as error:
        raise StartRefused(str(error)) from None
    settings.ensure_api_key()
    engine = make_engine(settings.db_url)
    hub = Hub()
    factory = make_session_factory(engine)
    manager = SessionManager(
        factory,
        settings.db_url,
        hub,
        worker_options(settings),
        settings.stale_after_s,
        settings.max_trainers,
        settings.training_population,
    )
    rating.install(manager)
    if settings.ray_address:
        refusal = cluster_refusal(settings.db_url, settings.checkpoint_root)
        if refusal is not None:
            raise StartRefused(refusal)
        manager.cluster = TrainingCluster(
            settings.ray_address, factory, settings.db_url, manager.options, hub
        )
    pools = Pools(
        manager,
        settings.pool_limit,
        settings.pool_every_s,
        settings.data_dir,
        settings.worker_threads,
        settings.pool_practising or max(1, (os.cpu_count() or 2) - 1),
    )
    viewer = viewer_from_settings(settings, hub, factory)
    playbacks, playback_viewer = episode_playback(settings)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        upgrade(engine, settings.data_dir / BACKUPS)
        await manager.open()
        if manager.cluster is not None:
            await run_in_threadpool(manager.cluster.open)
        viewer.start()
        playbacks.open()
        pools.open()
        await manager.resume_after_restart()
        yield
        await pools.close()
        playbacks.close_all()
        playback_viewer.stop()
        viewer.stop()
        await manager.close()
        if manager.cluster is not None:
            manager.cluster.close()
        engine.dispose()

    app = FastAPI(
        title="IDeepRL study platform",
        summary="Human advising studies in interactive deep reinforcement learning.",
        version=API_VERSION,
        lifespan=lifespan,
        generate_unique_id_function=operation_id,
        docs_url=None,  # served from local files by add_docs
        redoc_url=None,  # ReDoc has no offline bundle here; /docs is the reference
    )
    app.state.settings = settings
    app.state.engine = engine
    app.state.session_factory = factory
    app.state.hub = hub
    app.state.manager = manager
    app.state.viewer = viewer
    app.state.playbacks = playbacks
    app.state.playback_viewer = playback_viewer
    app.state.participant_tokens = {}
    app.state.dashboard_logins = Logins(settings.dashboard_login_s)
    app.state.arrivals_by_address = WindowLimit()
    app.state.arrivals_by_study = WindowLimit()
    """The study links' rate limits (`server.routes.joining`)."""
    for router in (*ROUTERS, sessions.creation_router()):
        app.include_router(router)
    for router in (
        reports.router,
        pages.router,
        joining.router,
        viewing.router,
        dashboard.router,
        playback.router,
        viewer_proxy.router,
    ):
        app.include_router(router)
    app.mount("/static", pages.static_files(), name="static")
    app.add_middleware(
        RequestGuard,
        max_body_bytes=settings.max_request_bytes,
        guards={**credential_guards(settings), LOGIN: dashboard.require_login},
        describe=describe_run_field(),
    )
    app.add_middleware(SecurityHeaders)
    refuse = validation_error(run_field_home())
    app.add_exception_handler(RequestValidationError, refuse)  # type: ignore[arg-type]
    install_openapi(app)
    add_docs(app)

    @app.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, error: StarletteHTTPException) -> Response:
        if error.status_code == 405:  # Starlette names the first route's methods only
            methods = path_methods(request.app.openapi(), request.url.path)
            if methods:
                headers = {**(error.headers or {}), "Allow": ", ".join(methods)}
                error = StarletteHTTPException(405, error.detail, headers)
        return await http_exception_handler(request, error)

    @app.exception_handler(ServiceError)
    async def service_error(request: Request, error: ServiceError) -> JSONResponse:
        if isinstance(error, Invalid):
            return await unacceptable(request, error.field, error.message)
        return JSONResponse({"detail": error.message}, status_code=error.status_code)

    @app.exception_handler(FieldError)
    async def run_field_error(request: Request, error: FieldError) -> JSONResponse:
        """A run's value its declaration refuses (`learner.fields`), wherever in a request
        the run was read: the body's `run`."""
        field = f"run.{error.field}" if error.field else "run"
        return await unacceptable(request, field, str(error))

    return app


async def unacceptable(request: Request, field: str, message: str) -> JSONResponse:
    """The 422 of a well-formed value a service or the run refuses, at its body field."""
    loc = ["body", *field.split(".")]
    detail = [{"loc": loc, "msg": await without_input(request, message), "type": "value_error"}]
    return JSONResponse({"detail": detail}, status_code=422)


def app_from_env() -> FastAPI:
    return create_app(Settings())
