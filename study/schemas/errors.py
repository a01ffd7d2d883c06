"""The one error body of every response that fails (`server.openapi` declares it for every
route): FastAPI's own `{"detail": ...}`, written down; and the words of its problems that
the API's 422 and the command line's usage errors share (a `loc` step as a person reads
it, an unknown field with the fields its object has)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

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


_UNION_MEMBER = re.compile(
    r"^(function-(after|before|wrap|plain)|constrained-\w+|json-or-python)\["
)
_BASE_TYPE = re.compile(r"(?<![\w.])(str|int|float|bool|list|dict|bytes)(?![\w(])")


def readable(part: Any) -> Any:
    """A `loc` step as a person reads it: pydantic names a union's member by its validator
    chain (with a function's address, `functools.partial(<function ...> at 0x...)`); say
    the type it takes instead."""
    if not isinstance(part, str) or not (_UNION_MEMBER.match(part) or " at 0x" in part):
        return part
    kinds = _BASE_TYPE.findall(part)
    return kinds[-1] if kinds else "(one of the allowed kinds)"


LISTED = 40
"""Valid fields a message names at most; an object with more points to the API document."""
DOCUMENT = "the API document (/openapi.json) lists the valid ones"


def _resolved(root: dict[str, Any], nodes: list[Any]) -> list[dict[str, Any]]:
    """The schemas `nodes` stand for: references (into `root`) followed, unions and `allOf`
    opened; bounded, so a schema that refers to itself ends."""
    out: list[dict[str, Any]] = []
    stack = list(reversed(nodes))
    steps = 0
    while stack and steps < 256:
        steps += 1
        node = stack.pop()
        if not isinstance(node, dict):
            continue
        ref = node.get("$ref")
        if isinstance(ref, str) and ref.startswith("#/"):
            target: Any = root
            for key in ref[2:].split("/"):
                target = target.get(key) if isinstance(target, dict) else None
            stack.append(target)
            continue
        members = [m for k in ("anyOf", "oneOf", "allOf") for m in node.get(k, [])]
        if members:
            stack.extend(reversed(members))
        else:
            out.append(node)
    return out


def valid_fields(schema: dict[str, Any], path: Sequence[Any]) -> list[str] | None:
    """The fields of the object at `path` (a pydantic `loc`, the body's part of it) in the
    JSON `schema` of what was validated; None where the path leads to no one object (a
    union of objects that differ, a step the schema does not have)."""
    nodes = _resolved(schema, [schema])
    for part in path:
        tagged = [n for n in nodes if n.get("title") == part and "properties" in n]
        if tagged:  # a union's member, named by its model
            nodes = tagged
            continue
        ahead: list[Any] = []
        for node in nodes:
            properties = node.get("properties", {})
            if isinstance(part, str) and part in properties:
                ahead.append(properties[part])
            elif isinstance(part, str) and isinstance(node.get("additionalProperties"), dict):
                ahead.append(node["additionalProperties"])
            elif isinstance(part, int) and isinstance(node.get("items"), dict):
                ahead.append(node["items"])
        nodes = _resolved(schema, ahead)
    kinds = {tuple(n["properties"]) for n in nodes if isinstance(n.get("properties"), dict)}
    return list(kinds.pop()) if len(kinds) == 1 else None


def valid_listed(valid: Sequence[str] | None) -> str:
    """Where the valid fields are: named, up to `LISTED` of them, else the API document."""
    return f"valid fields: {', '.join(valid)}" if valid and len(valid) <= LISTED else DOCUMENT


def unknown_field(name: str, valid: Sequence[str] | None) -> str:
    """The message for an unknown field `name` (a plain identifier) of an object whose
    fields are `valid` (None: not known)."""
    return f"unknown field '{name}'; {valid_listed(valid)}"
