"""The sorting scenario: a PyBullet robot arm sorting red and blue objects onto two tables.

`import sim` registers the Gymnasium id `ideeprl/Sorting-v0`, whose class is
`sim.SortingEnv` (`gym.make("sim:ideeprl/Sorting-v0")` imports it for you); see
docs/architecture.md ("sim: the scenario") for the contract.
PyBullet is imported only when the environment itself is first used, so a viewer or an
analysis script can use the actions, rules, oracle and scene types without it.
"""

from typing import Any

import gymnasium

from sim.actions import ACTION_NAMES, Action
from sim.bodies import BodySpec, Box, Cylinder, Geometry, Mesh, MeshFile, MotionFrame, Pose, Sphere
from sim.rewards import REWARD_SCHEMES, rescore, step_penalty
from sim.rules import COLORS, OBJECTS, SHAPES, SortRule, oracle_action
from sim.scenario import ScenarioOptions

ENV_ID = "ideeprl/Sorting-v0"

if ENV_ID not in gymnasium.registry:
    # gym.make handles `max_episode_steps` itself (a TimeLimit wrapper), to the same effect.
    gymnasium.register(id=ENV_ID, entry_point="sim.env:SortingEnv", max_episode_steps=250)


def __getattr__(name: str) -> Any:
    if name == "SortingEnv":
        from sim.env import SortingEnv

        return SortingEnv
    raise AttributeError(f"module 'sim' has no attribute {name!r}")


__all__ = [
    "ACTION_NAMES",
    "COLORS",
    "ENV_ID",
    "OBJECTS",
    "REWARD_SCHEMES",
    "SHAPES",
    "Action",
    "BodySpec",
    "Box",
    "Cylinder",
    "Geometry",
    "Mesh",
    "MeshFile",
    "MotionFrame",
    "Pose",
    "ScenarioOptions",
    "SortRule",
    "SortingEnv",
    "Sphere",
    "oracle_action",
    "rescore",
    "step_penalty",
]
