"""Declared fields: a description of something (a run, a session) as a tree of frozen
dataclasses, each field with its docstring under it and, for a number, its range beside it.

Everything else is derived from the declaration, never written again:
- `leaves(cls)`: the tree's fields flattened (path, type, choices, range, default, doc);
- `check(leaf, value)`: one value checked against its declaration; the error names the
  field and what it allows, and never repeats the value (input is untrusted);
- `build(cls, data)`: the dataclass from JSON, every value checked, unknown names refused;
- `to_json(obj)`: back to JSON;
- `add_arguments(parser, cls)`: one command-line flag per leaf (`--batch-size`), its help
  from the docstring and range; `given_arguments(args, cls)` reads back the ones given;
- `study.schemas.runs` makes the REST body and its OpenAPI schema from the same leaves,
  and `study.services.columns` the export's columns.

A field's range is declared with `bounded(default, minimum, maximum)`; a field's role in a
study (what the comparability audit does with it) with `role=`. Torch-free.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import re
import types
import typing
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from functools import cache
from typing import Any, Literal

from learner.docstrings import field_docstrings

ROLES = ("setting", "treatment", "seed", "numerics", "scale")
"""What a field is to a study. `setting`: compared methods must share it (the audit flags a
difference); `treatment`: who advises and how (what a comparison is about); `seed`: differs
between agents by design; `numerics`: how the same function is computed (device, threads,
precision); `scale`: how long a run goes on (the report cuts curves to the shortest)."""


def bounded(
    default: Any,
    minimum: float | None = None,
    maximum: float | None = None,
    *,
    role: str = "setting",
    exclusive_minimum: bool = False,
    column: str | None = None,
    max_length: int | None = None,
    pattern: str | None = None,
) -> Any:
    """A dataclass field with its range (numbers), role and export column declared once."""
    assert role in ROLES, role
    metadata = {
        "minimum": minimum,
        "maximum": maximum,
        "role": role,
        "exclusive_minimum": exclusive_minimum,
        "column": column,
        "max_length": max_length,
        "pattern": pattern,
    }
    if isinstance(default, dict | list):
        return dataclasses.field(default_factory=lambda: type(default)(default), metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def group(factory: Callable[[], Any], *, prefix: str = "") -> Any:
    """A nested dataclass field; its leaves' export columns get `prefix` (`config_`)."""
    return dataclasses.field(default_factory=factory, metadata={"prefix": prefix})


class FieldError(ValueError):
    """A value that its declaration does not allow; `field` is its dotted path."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field = field


@dataclass(frozen=True)
class Leaf:
    """One declared value of a tree of dataclasses."""

    path: tuple[str, ...]
    """Where it sits: ("config", "batch_size")."""
    kind: type
    """bool, int, float, str, or dict (a JSON object, e.g. a sort rule's map)."""
    optional: bool
    """None is allowed."""
    choices: tuple[Any, ...] | None
    """The allowed values of a `Literal`."""
    minimum: float | None
    maximum: float | None
    exclusive_minimum: bool
    max_length: int | None
    default: Any
    doc: str
    role: str
    column: str
    """Its column in the export (`config_batch_size`, `reward_scheme`)."""
    also_text: bool = False
    """A `str | dict` leaf: a name or a JSON object (the sort rule)."""
    pattern: str | None = None
    """A text's allowed characters, as a regular expression it must match whole."""

    @property
    def name(self) -> str:
        return self.path[-1]

    @property
    def dotted(self) -> str:
        return ".".join(self.path)

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    def allowed(self) -> str:
        """What the field allows, in words: 'an integer from 1 to 100000'."""
        if self.choices is not None:
            text = "one of " + ", ".join(json.dumps(c) for c in self.choices)
        elif self.kind is bool:
            text = "true or false"
        elif self.kind in (int, float):
            noun = "an integer" if self.kind is int else "a number"
            low, high = _number(self.minimum, self.kind), _number(self.maximum, self.kind)
            if low is not None and high is not None:
                op = "above" if self.exclusive_minimum else "from"
                text = f"{noun} {op} {low} to {high}"
            elif low is not None:
                text = f"{noun} {'above' if self.exclusive_minimum else 'of at least'} {low}"
            else:
                text = noun
        elif self.kind is dict:
            text = (
                "a text or a JSON object"
                if self.also_text
                else "a JSON object of texts, numbers and true/false"
            )
        else:
            text = "a text"
            if self.max_length:
                text += f" of at most {self.max_length} characters"
            if self.pattern:
                text += f" matching {self.pattern}"
        if self.kind is dict and self.max_length:
            text += f" (at most {self.max_length} characters)"
        return text + (", or null" if self.optional else "")


def _number(value: float | None, kind: type) -> str | None:
    if value is None:
        return None
    if kind is int or float(value).is_integer():
        return str(int(value))
    return f"{value:g}"


def leaves(cls: type) -> tuple[Leaf, ...]:
    """Every leaf of the dataclass tree under `cls`, in field order."""
    return _cached_leaves(cls)  # a class is hashable, which mypy cannot see of a dataclass's


@cache
def _cached_leaves(cls: type) -> tuple[Leaf, ...]:
    return tuple(_leaves(cls, (), ""))


def _leaves(cls: type, path: tuple[str, ...], prefix: str) -> Iterator[Leaf]:
    hints = typing.get_type_hints(cls)
    docs = _docs(cls)
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        if dataclasses.is_dataclass(hint):
            yield from _leaves(hint, (*path, f.name), prefix + f.metadata.get("prefix", ""))  # type: ignore[arg-type]
            continue
        kind, optional, choices, also_text = _kind(hint)
        meta = f.metadata
        factory = f.default_factory
        default = factory() if f.default is dataclasses.MISSING and callable(factory) else f.default
        yield Leaf(
            path=(*path, f.name),
            kind=kind,
            optional=optional,
            choices=choices,
            minimum=meta.get("minimum"),
            maximum=meta.get("maximum"),
            exclusive_minimum=bool(meta.get("exclusive_minimum")),
            max_length=meta.get("max_length"),
            default=default,
            doc=docs.get(f.name, ""),
            role=meta.get("role", "setting"),
            column=meta.get("column") or prefix + f.name,
            also_text=also_text,
            pattern=meta.get("pattern"),
        )


def _docs(cls: type) -> dict[str, str]:
    docs: dict[str, str] = {}
    for base in reversed(cls.__mro__):
        if dataclasses.is_dataclass(base):
            docs.update(field_docstrings(base))
    return docs


def _kind(hint: Any) -> tuple[type, bool, tuple[Any, ...] | None, bool]:
    """(kind, optional, choices, also_text) of a field's type hint."""
    origin = typing.get_origin(hint)
    optional = False
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        optional = len(args) < len(typing.get_args(hint))
        if len(args) == 2 and str in args and any(typing.get_origin(a) is dict for a in args):
            return dict, optional, None, True
        hint = args[0]
        origin = typing.get_origin(hint)
    if origin is Literal:
        return str, optional, typing.get_args(hint), False
    if origin is dict:
        return dict, optional, None, False
    if hint in (bool, int, float, str):
        return hint, optional, None, False
    raise TypeError(f"no declared kind for {hint!r}")


def check(leaf: Leaf, value: Any) -> Any:
    """`value` if the leaf allows it (ints given for a float become floats); else a
    `FieldError` naming the field and what it allows, without the value."""
    problem = FieldError(leaf.dotted, f"{leaf.dotted} must be {leaf.allowed()}")
    if value is None:
        if leaf.optional:
            return None
        raise problem
    if leaf.choices is not None:
        if isinstance(value, str) and value in leaf.choices:
            return value
        raise problem
    if leaf.kind is bool:
        if isinstance(value, bool):
            return value
        raise problem
    if leaf.kind in (int, float):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise problem
        if leaf.kind is int and not isinstance(value, int):
            raise problem
        if isinstance(value, float) and not math.isfinite(value):
            raise problem
        if leaf.minimum is not None and (
            value < leaf.minimum or (leaf.exclusive_minimum and value == leaf.minimum)
        ):
            raise problem
        if leaf.maximum is not None and value > leaf.maximum:
            raise problem
        return float(value) if leaf.kind is float else value
    if leaf.kind is dict:
        if (isinstance(value, str) and leaf.also_text) or isinstance(value, Mapping):
            text = value if isinstance(value, str) else json.dumps(value)
            if leaf.max_length and len(text) > leaf.max_length:
                raise problem
            if isinstance(value, Mapping) and not all(
                isinstance(k, str) and _entry(v, leaf.also_text) for k, v in value.items()
            ):
                raise problem
            texts = [value] if isinstance(value, str) else [*value, *value.values()]
            for text in texts:
                if isinstance(text, str):
                    _storable(leaf, text)
            return value if isinstance(value, str) else dict(value)
        raise problem
    if not isinstance(value, str) or (leaf.max_length and len(value) > leaf.max_length):
        raise problem
    _storable(leaf, value)
    if leaf.pattern and not re.fullmatch(leaf.pattern, value):
        raise problem
    return value


def _entry(value: Any, text_only: bool) -> bool:
    """A JSON object's value a leaf allows: a text for a sort rule's map; a text, a finite
    number or true/false for an object of options."""
    if isinstance(value, str):
        return True
    if text_only:
        return False
    return isinstance(value, bool | int) or (isinstance(value, float) and math.isfinite(value))


def _storable(leaf: Leaf, text: str) -> None:
    """Text every database stores: no NUL (PostgreSQL refuses it), no lone surrogate."""
    if "\x00" in text:
        raise FieldError(leaf.dotted, f"{leaf.dotted} must not hold a NUL character")
    if any(0xD800 <= ord(c) <= 0xDFFF for c in text):
        raise FieldError(leaf.dotted, f"{leaf.dotted} must not hold a lone surrogate")


def check_object(obj: Any) -> None:
    """Check every leaf of a dataclass instance in place (ints given for floats become
    floats), then its class's rules across fields (`checked`), in order; raises
    `FieldError` (a `ValueError`). `@checked` makes it the class's `__post_init__`."""
    for leaf in leaves(type(obj)):
        if len(leaf.path) != 1:
            continue  # a nested dataclass checks its own
        value = getattr(obj, leaf.name)
        checked = check(leaf, value)
        if checked is not value:
            object.__setattr__(obj, leaf.name, checked)
    for rule in getattr(type(obj), "__rules__", ()):
        rule.check(obj)


@dataclass(frozen=True)
class AtLeast:
    """A rule across fields: `field` must be at least `other`, for the reason `why`."""

    field: str
    other: str
    why: str = ""

    def check(self, obj: Any) -> None:
        value, bound = getattr(obj, self.field), getattr(obj, self.other)
        if value < bound:  # both checked numbers by now: safe to show
            why = f": {self.why}" if self.why else ""
            raise FieldError(
                self.field, f"{self.field} ({value}) must be at least {self.other} ({bound}){why}"
            )


@dataclass(frozen=True)
class Needs:
    """A rule across fields: `field` switched on needs `other` switched on."""

    field: str
    other: str

    def check(self, obj: Any) -> None:
        if getattr(obj, self.field) and not getattr(obj, self.other):
            raise FieldError(self.field, f"{self.field} needs {self.other}=True")


Rule = AtLeast | Needs
_T = typing.TypeVar("_T", bound=type)


def checked(*rules: Rule) -> Callable[[_T], _T]:
    """Class decorator, under `@dataclass`: every instance is checked as it is made, each
    leaf against its declaration (`check_object`), then the `rules` across fields, in
    order. The rules are declared data, like the fields: the class writes no
    `__post_init__`, so making one (`build`, `dataclasses.replace`) never calls back into the
    module that declares it."""

    def decorate(cls: _T) -> _T:
        if "__post_init__" in vars(cls):
            raise TypeError(f"{cls.__name__}: @checked writes __post_init__; declare rules")
        cls.__post_init__ = check_object  # type: ignore[attr-defined]
        cls.__rules__ = rules  # type: ignore[attr-defined]
        return cls

    return decorate


def build(cls: type, data: Any, path: str = "", base: Any = None) -> Any:
    """`cls` from JSON `data`: unknown names refused, every value checked; fields `data`
    leaves out take `base`'s values (when given) or their defaults."""
    where = path or cls.__name__
    if not isinstance(data, Mapping):
        raise FieldError(path or "", f"{where} must be a JSON object")
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(data) - set(names))
    if unknown:
        first = f"{path}.{unknown[0]}" if path else unknown[0]
        raise FieldError(
            first,
            f"unknown field '{first if len(first) <= 64 else first[:64] + '...'}'; valid "
            f"fields{' of ' + path if path else ''}: {', '.join(names)}",
        )
    values: dict[str, Any] = {}
    by_name = {leaf.path[-1]: leaf for leaf in leaves(cls) if len(leaf.path) == 1}
    for name in names:
        dotted = f"{path}.{name}" if path else name
        inner = getattr(base, name) if base is not None else None
        if dataclasses.is_dataclass(hints[name]):
            if name in data:
                values[name] = build(hints[name], data[name], dotted, inner)
            elif inner is not None:
                values[name] = inner
            continue
        if name in data:
            leaf = dataclasses.replace(by_name[name], path=tuple(dotted.split(".")))
            values[name] = check(leaf, data[name])
        elif base is not None:
            values[name] = inner
    try:
        return cls(**values)
    except FieldError as error:
        field = f"{path}.{error.field}" if path and error.field else error.field or path
        raise FieldError(field, f"{path + '.' if path else ''}{error}") from None
    except (TypeError, ValueError) as error:
        raise FieldError(path, str(error)) from None


def to_json(obj: Any) -> dict[str, Any]:
    """The dataclass tree as plain JSON."""
    return json.loads(json.dumps(dataclasses.asdict(obj)))


def nest(values: Mapping[str, Any], cls: type) -> dict[str, Any]:
    """`{"batch_size": 32, "seed": 1}` (leaf names) as the tree's JSON
    (`{"config": {"batch_size": 32}, "seed": 1}`); an unknown name is a `FieldError`."""
    by_name = {leaf.name: leaf for leaf in leaves(cls)}
    out: dict[str, Any] = {}
    for name, value in values.items():
        leaf = by_name.get(name)
        if leaf is None:
            raise FieldError(
                name, f"unknown field {name[:64]}; valid fields: {', '.join(sorted(by_name))}"
            )
        node = out
        for part in leaf.path[:-1]:
            node = node.setdefault(part, {})
        node[leaf.name] = value
    return out


def flatten(data: Mapping[str, Any], cls: type) -> dict[str, Any]:
    """A tree's JSON by leaf name (the inverse of `nest` for what `data` holds)."""
    out: dict[str, Any] = {}
    for leaf in leaves(cls):
        node: Any = data
        for part in leaf.path:
            if not isinstance(node, Mapping) or part not in node:
                break
            node = node[part]
        else:
            out[leaf.name] = node
    return out


# --- the command line ------------------------------------------------------------------


def parse_text(leaf: Leaf, text: str) -> Any:
    """A flag's text as the leaf's value: numbers and booleans as JSON, `null`/`none` for an
    optional one, a sort rule as text or JSON; checked (`FieldError`)."""
    value: Any = text
    stripped = text.strip()
    if leaf.optional and stripped.lower() in ("null", "none"):
        value = None
    elif leaf.kind is bool:
        lowered = stripped.lower()
        value = {"true": True, "false": False, "1": True, "0": False}.get(lowered, text)
    elif leaf.kind in (int, float):
        try:
            value = json.loads(stripped)
        except json.JSONDecodeError:
            value = text
    elif leaf.kind is dict and stripped.startswith("{"):
        try:
            value = json.loads(stripped)
        except json.JSONDecodeError:
            raise FieldError(leaf.dotted, f"{leaf.dotted} is not valid JSON") from None
    try:
        return check(leaf, value)
    except FieldError as error:  # a flag's text: say what was given, as typed
        shown = text if len(text) <= 40 else text[:40] + "..."
        raise FieldError(error.field, f"{error} (given: {shown!r})") from None


def add_arguments(
    parser: argparse.ArgumentParser | Any,
    cls: type,
    *,
    skip: tuple[str, ...] = (),
    defaults: Mapping[str, str] | None = None,
) -> None:
    """One flag per leaf of `cls` (but `skip`), named after it, its help from its docstring
    and declaration; unset flags are absent from the namespace (`given_arguments`)."""
    defaults = defaults or {}
    for leaf in leaves(cls):
        if leaf.name in skip:
            continue
        default = defaults.get(leaf.name, _default_text(leaf))
        parser.add_argument(
            leaf.flag,
            dest=f"spec__{leaf.name}",
            metavar=_metavar(leaf),
            type=_argument_type(leaf),
            default=argparse.SUPPRESS,
            help=f"{leaf.doc} [{leaf.allowed()}; default {default}]".replace("%", "%%"),
        )


def given_arguments(args: argparse.Namespace) -> dict[str, Any]:
    """The leaves whose flags were given, by leaf name (already checked)."""
    return {
        key.removeprefix("spec__"): value
        for key, value in vars(args).items()
        if key.startswith("spec__")
    }


def _argument_type(leaf: Leaf) -> Callable[[str], Any]:
    def convert(text: str) -> Any:
        try:
            return parse_text(leaf, text)
        except FieldError as error:
            raise argparse.ArgumentTypeError(str(error)) from None

    convert.__name__ = leaf.name
    return convert


def _metavar(leaf: Leaf) -> str:
    if leaf.choices is not None:
        return "{" + ",".join(map(str, leaf.choices)) + "}"
    if leaf.kind is dict and not leaf.also_text:
        return "JSON"
    return {bool: "BOOL", int: "N", float: "X", dict: "RULE"}.get(leaf.kind, "TEXT")


def _default_text(leaf: Leaf) -> str:
    if leaf.default is None:
        return "none"
    return json.dumps(leaf.default) if not isinstance(leaf.default, str) else leaf.default
