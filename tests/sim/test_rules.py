"""Sorting rules and the oracle that follows them."""

import json

import pytest

import sim
from sim.rules import SortRule

ALL = [(s, c) for s in sim.SHAPES for c in sim.COLORS]


def test_color_rule_is_the_papers_blue_right_red_left() -> None:
    rule = SortRule.parse("color")
    assert rule.side("cube", "blue") == "right"
    assert all(
        rule.side(s, "red") == "left" and rule.side(s, "blue") == "right" for s in sim.SHAPES
    )


def test_shape_rule_sends_cubes_left_and_round_objects_right() -> None:
    rule = SortRule.parse("shape")
    assert [rule.side(s, c) for s, c in ALL] == ["left", "left"] + ["right"] * 4


def test_an_explicit_map_round_trips_through_its_spec_and_json() -> None:
    mapping = {f"{s}/{c}": "left" if s == "disk" else "right" for s, c in ALL}
    rule = SortRule.parse(mapping)
    assert rule.side("disk", "blue") == "left" and rule.side("cube", "red") == "right"
    assert rule.to_spec() == mapping
    assert SortRule.parse(json.dumps(rule.to_spec())) == rule
    assert SortRule.parse(rule) is rule
    assert SortRule.parse(SortRule.parse("shape").to_spec()) == SortRule.parse("shape")


@pytest.mark.parametrize(
    "spec",
    [
        "colour",
        "",
        42,
        ["color"],
        "{not json",
        {"cube/red": "left"},  # five objects missing
        {**{f"{s}/{c}": "left" for s, c in ALL}, "sphere/red": "left"},
        {**{f"{s}/{c}": "left" for s, c in ALL}, "cube/red": "up"},
    ],
)
def test_invalid_rules_are_rejected_naming_the_valid_forms(spec: object) -> None:
    with pytest.raises(ValueError) as error:
        SortRule.parse(spec)  # type: ignore[arg-type]
    message = str(error.value)
    assert '"color"' in message and '"shape"' in message and '"cube/red"' in message


@pytest.mark.parametrize(
    ("station", "held", "rule", "expected"),
    [
        ("center", None, "color", sim.Action.GRAB),
        ("left", None, "color", sim.Action.GRAB),
        ("center", ("cube", "blue"), "color", sim.Action.MOVE_RIGHT),
        ("left", ("cube", "blue"), "color", sim.Action.MOVE_RIGHT),
        ("right", ("cube", "blue"), "color", sim.Action.DROP),
        ("right", ("disk", "red"), "color", sim.Action.MOVE_LEFT),
        ("left", ("disk", "red"), "color", sim.Action.DROP),
        ("center", ("cube", "blue"), "shape", sim.Action.MOVE_LEFT),
        ("right", ("cylinder", "red"), "shape", sim.Action.DROP),
    ],
)
def test_oracle_goes_to_the_held_objects_side_then_drops(
    station: str, held: tuple[str, str] | None, rule: str, expected: sim.Action
) -> None:
    info = {
        "station": station,
        "held": "" if held is None else "/".join(held),
    }
    assert sim.oracle_action(info, rule) == expected
