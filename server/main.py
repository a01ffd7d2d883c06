"""The FastAPI app: `create_app(settings)`; `uvicorn --factory server.main:app_from_env
--ws-per-message-deflate false` (see `UVICORN_OPTIONS`)."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from fastapi.security import HTTPAuthorizationCredentials
from fastapi.security.utils import get_authorization_scheme_param
from starlette.exceptions import HTTPException as StarletteHTTPException

from server.db.engine import make_engine, make_session_factory
from server.db.migrate import BACKUPS, upgrade
from server.deps import API_KEY_HEADER, participant_session, require_researcher
from server.guard import LOGIN, RequestGuard
from server.headers import SecurityHeaders, validation_error, without_input
from server.live.hub import Hub
from server.live.manager import SessionManager
from server.logins import Logins
from server.openapi import install as install_openapi
from server.openapi import operation_id, path_methods
from server.routes import ROUTERS, dashboard, pages, reports, viewing
from server.routes.docs import add_docs
from server.services.errors import Invalid, ServiceError
from server.settings import Settings
from server.viewer import proxy as viewer_proxy
from server.viewer import viewer_from_settings
from server.worker.worker import WorkerOptions

UVICORN_OPTIONS: dict[str, Any] = {"ws_per_message_deflate": False}
"""How uvicorn must run this app: its only websocket is the 3-D view's relay, whose stream of
pose updates viser itself sends uncompressed ("compression can be too slow"); deflating it
again in the web process would cost that process the CPU its participants' requests need."""


def worker_options(settings: Settings) -> WorkerOptions:
    return WorkerOptions(
        data_dir=settings.data_dir,
        checkpoint_every_episodes=settings.checkpoint_every_episodes,
        flush_every_steps=settings.flush_every_steps,
        heartbeat_s=settings.heartbeat_s,
        idle_limit_s=settings.idle_limit_s,
        torch_threads=settings.worker_threads,
        nice=settings.trainer_nice,
        keep_replay_memory=settings.keep_replay_memory,
    )


def credential_guards(settings: Settings) -> dict[Any, Any]:
    """What `RequestGuard` checks before reading a body, per dependency a route declares."""

    def researcher(request: Request) -> None:
        require_researcher(settings, request.headers.get(API_KEY_HEADER))

    def participant(request: Request) -> None:
        scheme, token = get_authorization_scheme_param(request.headers.get("Authorization"))
        given = None
        if scheme.lower() == "bearer" and token:
            given = HTTPAuthorizationCredentials(scheme=scheme, credentials=token)
        participant_session(request, given)

    return {
        "APIKeyHeader": researcher,
        "HTTPBearer": participant,
        LOGIN: dashboard.require_login,
    }


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()
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
    )
    viewer = viewer_from_settings(settings, hub, factory)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        upgrade(engine, settings.data_dir / BACKUPS)
        await manager.open()
        viewer.start()
        yield
        viewer.stop()
        await manager.close()
        engine.dispose()

    app = FastAPI(
        title="IDeepRL study platform",
        summary="Human advising studies in interactive deep reinforcement learning.",
        version="0.1.0",
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
    app.state.participant_tokens = {}
    app.state.dashboard_logins = Logins(settings.dashboard_login_s)
    for router in ROUTERS:
        app.include_router(router)
    for router in (
        reports.router,
        pages.router,
        viewing.router,
        dashboard.router,
        viewer_proxy.router,
    ):
        app.include_router(router)
    app.mount("/static", pages.static_files(), name="static")
    app.add_middleware(
        RequestGuard, max_body_bytes=settings.max_request_bytes, guards=credential_guards(settings)
    )
    app.add_middleware(SecurityHeaders)
    app.add_exception_handler(RequestValidationError, validation_error)  # type: ignore[arg-type]
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
            message = await without_input(request, error.message)
            detail = [{"loc": ["body", error.field], "msg": message, "type": "value_error"}]
            return JSONResponse({"detail": detail}, status_code=422)
        return JSONResponse({"detail": error.message}, status_code=error.status_code)

    return app


def app_from_env() -> FastAPI:
    return create_app(Settings())
