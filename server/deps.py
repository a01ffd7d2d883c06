"""Typed dependencies of the routes: the database session, the settings, the session
manager, and the two kinds of credentials (researcher key, participant token)."""

from __future__ import annotations

import secrets
from collections.abc import Callable, Iterator
from typing import Annotated

from fastapi import Depends, HTTPException, Request, Security
from fastapi.security import APIKeyHeader, HTTPAuthorizationCredentials, HTTPBearer
from fastapi.security.utils import get_authorization_scheme_param
from sqlalchemy.orm import Session

from server.live.advising import ParticipantSession
from server.live.manager import SessionManager
from study.services.sessions import session_for_token
from study.settings import Settings

API_KEY_HEADER = "X-API-Key"
_api_key = APIKeyHeader(name=API_KEY_HEADER, auto_error=False, description="Researcher key.")
_bearer = HTTPBearer(auto_error=False, description="Participant token from their link.")


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


def get_db(request: Request) -> Iterator[Session]:
    with request.app.state.session_factory() as db:
        yield db


def get_manager(request: Request) -> SessionManager:
    return request.app.state.manager


SettingsDep = Annotated[Settings, Depends(get_settings)]
DbDep = Annotated[Session, Depends(get_db)]
ManagerDep = Annotated[SessionManager, Depends(get_manager)]


def require_researcher(
    settings: SettingsDep, key: Annotated[str | None, Security(_api_key)]
) -> None:
    if not key:
        raise HTTPException(
            401,
            f"this endpoint needs the researcher key in the {API_KEY_HEADER} header "
            "(`ideeprl serve` prints it)",
            headers={"WWW-Authenticate": "APIKey"},
        )
    assert settings.api_key, "the app always has a key"
    if not secrets.compare_digest(key.encode(), settings.api_key.encode()):
        raise HTTPException(403, f"the {API_KEY_HEADER} header does not hold the researcher key")


def participant_session(
    request: Request,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Security(_bearer)],
) -> ParticipantSession:
    if credentials is None or not credentials.credentials:
        raise HTTPException(
            401,
            "this endpoint needs the participant token from the link, as "
            "`Authorization: Bearer TOKEN`",
            headers={"WWW-Authenticate": "Bearer"},
        )
    # Known tokens are kept in memory: the advice loop should not query for them each time.
    token = credentials.credentials
    known: dict[str, ParticipantSession] = request.app.state.participant_tokens
    if token in known:
        return known[token]
    with request.app.state.session_factory() as db:
        session = session_for_token(db, token)
        if session is None:
            raise HTTPException(
                403, "this participant token is not valid; use the link you were given"
            )
        spec = session.spec
        found = ParticipantSession(session.id, spec.advice_budget, session.condition, spec.task)
    known[token] = found
    return found


def credential_guards(settings: Settings) -> dict[str, Callable[[Request], None]]:
    """The two credentials checked by `server.guard.RequestGuard` before a body is read, by
    the security scheme a route declares: the same checks as the dependencies above."""

    def researcher(request: Request) -> None:
        require_researcher(settings, request.headers.get(API_KEY_HEADER))

    def participant(request: Request) -> None:
        scheme, token = get_authorization_scheme_param(request.headers.get("Authorization"))
        given = None
        if scheme.lower() == "bearer" and token:
            given = HTTPAuthorizationCredentials(scheme=scheme, credentials=token)
        participant_session(request, given)

    return {"APIKeyHeader": researcher, "HTTPBearer": participant}


ResearcherDep = Depends(require_researcher)
ParticipantDep = Annotated[ParticipantSession, Depends(participant_session)]
