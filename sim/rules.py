"""Which side table each object belongs on, and the action that sorts it.

A study may change the task (SPEC 1, "Sorting rule"), so the rule is data: a map from
every (shape, color) to a side, written as a short spec that a database row can hold.
"""

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

from sim.actions import Action

SHAPES: tuple[str, ...] = ("cube", "cylinder", "disk")
COLORS: tuple[str, ...] = ("red", "blue")
SIDES: tuple[str, ...] = ("left", "right")
OBJECTS: tuple[str, ...] = tuple(f"{s}/{c}" for s in SHAPES for c in COLORS)
"""The six objects as "shape/color", in the order of `info["on_center"]`."""
Side = Literal["left", "right"]
SortRuleSpec = str | Mapping[str, str]

_NAMED: dict[str, dict[tuple[str, str], str]] = {
    # The paper's example: a blue cube goes right, so red goes left.
    "color": {(s, c): "right" if c == "blue" else "left" for s in SHAPES for c in COLORS},
    # Square things left, round things (cylinders and disks) right.
    "shape": {(s, c): "left" if s == "cube" else "right" for s in SHAPES for c in COLORS},
}
VALID_FORMS = (
    'a sort rule is "color" (blue right, red left), "shape" (cubes left, cylinders and disks '
    'right), or a map from each of the six objects "shape/color" (shapes cube, cylinder, disk; '
    'colors red, blue) to "left" or "right", e.g. {"cube/red": "left", "cube/blue": "right", '
    '...} (a dict, the same as a JSON string, or as text "cube/red=left;cube/blue=right;...")'
)


@dataclass(frozen=True)
class SortRule:
    """The side table every object belongs on."""

    name: str
    """`"color"`, `"shape"`, or `"map"` for an explicit map."""
    sides: tuple[tuple[str, str, str], ...]
    """(shape, color, side) for all six objects, in `SHAPES` x `COLORS` order."""

    @classmethod
    def parse(cls, spec: "SortRuleSpec | SortRule") -> "SortRule":
        """A rule from `"color"`, `"shape"`, a `{"shape/color": side}` map (or its JSON), or
        a `SortRule`; anything else raises `ValueError` naming the valid forms."""
        if isinstance(spec, SortRule):
            return spec
        if isinstance(spec, str):
            text = spec.strip()
            if text.startswith("{"):
                try:
                    spec = json.loads(text)
                except json.JSONDecodeError as error:
                    raise ValueError(
                        f"sort rule {spec!r} is not valid JSON ({error}); {VALID_FORMS}"
                    ) from None
            elif text.lower() in _NAMED:
                return cls._from_map(text.lower(), _NAMED[text.lower()])
            elif "=" in text:  # the exports' plain text: "cube/red=left;cube/blue=right;..."
                pairs = [part.partition("=") for part in text.split(";") if part.strip()]
                spec = {key.strip(): side.strip() for key, _, side in pairs}
            else:
                raise ValueError(f"unknown sort rule {spec!r}; {VALID_FORMS}")
        if not isinstance(spec, Mapping):
            raise ValueError(f"sort rule must be a string or a map, got {spec!r}; {VALID_FORMS}")
        return cls._from_map("map", _parse_map(spec))

    @classmethod
    def _from_map(cls, name: str, mapping: Mapping[tuple[str, str], str]) -> "SortRule":
        return cls(name, tuple((s, c, mapping[s, c]) for s in SHAPES for c in COLORS))

    def side(self, shape: str, color: str) -> Side:
        """The side table where a `color` `shape` belongs."""
        for s, c, side in self.sides:
            if (s, c) == (shape, color):
                return side  # type: ignore[return-value]
        raise ValueError(f"no object {shape}/{color}: shapes are {SHAPES}, colors {COLORS}")

    def to_spec(self) -> str | dict[str, str]:
        """A JSON-able spec that `parse` turns back into this rule."""
        if self.name in _NAMED:
            return self.name
        return {f"{s}/{c}": side for s, c, side in self.sides}


def _parse_map(spec: Mapping[Any, Any]) -> dict[tuple[str, str], str]:
    mapping: dict[tuple[str, str], str] = {}
    for key, side in spec.items():
        shape, _, color = str(key).partition("/")
        if shape not in SHAPES or color not in COLORS:
            raise ValueError(f"sort rule key {key!r} is not an object; {VALID_FORMS}")
        if side not in SIDES:
            raise ValueError(f"sort rule sends {key} to {side!r}, not a side; {VALID_FORMS}")
        mapping[shape, color] = side
    missing = [f"{s}/{c}" for s in SHAPES for c in COLORS if (s, c) not in mapping]
    if missing:
        raise ValueError(f"sort rule says nothing about {', '.join(missing)}; {VALID_FORMS}")
    return mapping


def oracle_action(info: Mapping[str, Any], sort_rule: "SortRuleSpec | SortRule") -> int:
    """The correct next action, from the ground truth in `info`.

    Holding: go to the held object's side, then drop. Not holding: grab (a no-op once the
    center is empty, which only happens after the episode has ended).
    """
    rule = SortRule.parse(sort_rule)
    held = info["held"]
    if not held:  # "" (the env's info), or None in a hand-made one
        return int(Action.GRAB)
    shape, color = held.split("/") if isinstance(held, str) else (held["shape"], held["color"])
    side = rule.side(shape, color)
    if info["station"] == side:
        return int(Action.DROP)
    return int(Action.MOVE_RIGHT if side == "right" else Action.MOVE_LEFT)
