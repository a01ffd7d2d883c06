"""The one error body of every response that fails (`server.openapi` declares it for every
route): FastAPI's own `{"detail": ...}`, written down."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class ErrorItem(BaseModel):
    """One problem with the request (422), as FastAPI and pydantic report it."""

    model_config = ConfigDict(extra="allow")

    loc: list[str | int] = Field(description='Where: e.g. ["body", "name"] or ["path", "id"].')
    msg: str = Field(description="What is wrong, in words.")
    type: str = Field(description="pydantic's error type, e.g. missing, value_error.")


class ErrorBody(BaseModel):
    """Every error response: a sentence that says what to do, or (422) the problems."""

    detail: str | list[ErrorItem] = Field(
        description="A message (401, 403, 404, 409, 413, ...) or, for 422, one item per problem."
    )
