"""Request bodies generated from declared dataclasses (`learner.fields`): the REST body of a
run is `RunSpec`'s tree as pydantic models, so the OpenAPI schema shows every field with its
docstring, type and range, and a bad value is a 422 naming the field and what it allows.

The checks are the declaration's own (`learner.fields.check`), never restated here; the
body's values then go through `RunSpec.from_json` like every other entry point's."""

from __future__ import annotations

import dataclasses
import typing
from functools import cache
from typing import Annotated, Any

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, WithJsonSchema, create_model

from learner.fields import FieldError, Leaf, check, leaves
from study.schemas.types import NO_NUL, plain_text, whole_number


def leaf_schema(leaf: Leaf) -> dict[str, Any]:
    """The JSON schema of one declared value."""
    schema: dict[str, Any]
    if leaf.choices is not None:
        schema = {"type": "string", "enum": list(leaf.choices)}
    elif leaf.kind is bool:
        schema = {"type": "boolean"}
    elif leaf.kind in (int, float):
        schema = {"type": "integer" if leaf.kind is int else "number"}
        number = int if leaf.kind is int else float
        if leaf.minimum is not None:
            key = "exclusiveMinimum" if leaf.exclusive_minimum else "minimum"
            schema[key] = number(leaf.minimum)
        if leaf.maximum is not None:
            schema["maximum"] = number(leaf.maximum)
    elif leaf.kind is dict:
        # printable ASCII without quote or backslash: each character one in the JSON text
        # `check` measures, so 10 entries of these lengths take at most 340 of its 400
        plain = r"^[ !#-\[\]-~]*$"
        mapping = {
            "type": "object",
            "propertyNames": {"maxLength": 16, "pattern": plain},
            "additionalProperties": {"type": "string", "maxLength": 10, "pattern": plain},
            "maxProperties": 10,
        }
        if leaf.also_text:
            text = {"type": "string", "maxLength": leaf.max_length or 400, "pattern": NO_NUL}
            schema = {"anyOf": [text, mapping]}
        else:  # an object of options: texts, finite numbers, true/false
            schema = {
                "type": "object",
                "propertyNames": {"maxLength": 40, "pattern": plain},
                "additionalProperties": {
                    "anyOf": [
                        {"type": "string", "maxLength": 200, "pattern": plain},
                        {"type": "number"},
                        {"type": "boolean"},
                    ]
                },
                "maxProperties": 20,
            }
    else:
        schema = {"type": "string"}
        if leaf.max_length:
            schema["maxLength"] = leaf.max_length
        # checked whole (re.fullmatch), and without NUL; a JSON Schema pattern is a search
        schema["pattern"] = f"^(?:{leaf.pattern})$" if leaf.pattern else NO_NUL
    if leaf.optional:
        schema = {"anyOf": [schema, {"type": "null"}]}
    return {**schema, "description": f"{leaf.doc} [{leaf.allowed()}]"}


def _validator(leaf: Leaf) -> Any:
    def validate(value: Any) -> Any:
        texts = [*value, *value.values()] if isinstance(value, dict) else [value]
        for text in texts:  # NUL: the same 422 as every other text field of a body
            if isinstance(text, str):
                plain_text(text)
        if leaf.kind is int:
            value = whole_number(value)
        try:
            return check(leaf, value)
        except FieldError as error:
            raise ValueError(str(error)) from None

    return validate


def leaf_type(leaf: Leaf, schema: dict[str, Any] | None = None) -> Any:
    """A declared value as a body's field: checked by its declaration, and shown as `schema`
    (by default `leaf_schema`'s)."""
    shown = leaf_schema(leaf) if schema is None else schema
    return Annotated[Any, BeforeValidator(_validator(leaf)), WithJsonSchema(shown)]


@cache
def body_model(cls: type, name: str | None = None) -> type[BaseModel]:
    """A pydantic model of the dataclass tree under `cls`: every field optional (unset ones
    take their defaults where the body is read), unknown fields refused."""
    hints = typing.get_type_hints(cls)
    by_name = {leaf.path[0]: leaf for leaf in leaves(cls) if len(leaf.path) == 1}
    fields: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if dataclasses.is_dataclass(hints[f.name]):
            inner = body_model(hints[f.name])
            fields[f.name] = (inner, Field(default=None))  # an object, or left out
            continue
        fields[f.name] = (leaf_type(by_name[f.name]), Field(default=None))
    model = create_model(
        name or cls.__name__,
        __config__=ConfigDict(extra="forbid"),
        __doc__=(cls.__doc__ or "").strip(),
        **fields,
    )
    return model


def given(body: BaseModel) -> dict[str, Any]:
    """The values a body set (its nested models too), as JSON for `from_json`."""
    return body.model_dump(exclude_unset=True)
