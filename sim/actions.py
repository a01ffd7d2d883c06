"""The agent's four actions, with the ids the paper's network outputs."""

from enum import IntEnum


class Action(IntEnum):
    """Ids in the paper's order; the Q-network's output `i` is `Action(i)`."""

    GRAB = 0
    MOVE_RIGHT = 1
    MOVE_LEFT = 2
    DROP = 3


ACTION_NAMES: tuple[str, ...] = ("grab", "move right", "move left", "drop")
"""Words a person reads in the advice menu, indexed by action id."""
