"""The scenario's options beyond motion and sorting rule, as one JSON-able value.

Each rate's range is declared beside it (the `minimum`/`maximum` metadata that
`learner.fields` reads, so the REST schema, the flags and the checks take it from here).
A study stores them with each run and compares only runs that share them (the report's
comparability audit), so they travel as one object, checked once, from every entry point
(`ideeprl train`, the REST session body, `ideeprl batch`) to `SortingEnv(**options)`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from sim.rewards import RewardScheme, check_reward_scheme


@dataclass(frozen=True)
class ScenarioOptions:
    """What a step costs and how imperfect the scene is (`SortingEnv`'s docstring)."""

    reward_scheme: RewardScheme = "paper"
    """What a step without a placement costs (`sim.rewards`): paper (the paper's text: -0.01
    after the 18th step), authors-autonomous (the authors' DeepRL script: 0 up to the 19th
    step, then -0.01 x (n - 19)), authors-interactive (their IDeepRL scripts: -0.01 from the
    first step)."""
    grasp_failure_rate: float = dataclasses.field(
        default=0.0, metadata={"minimum": 0.0, "maximum": 1.0}
    )
    """Chance that a grab comes back empty."""
    knock_off_rate: float = dataclasses.field(
        default=0.0, metadata={"minimum": 0.0, "maximum": 1.0}
    )
    """Chance that a grab knocks one other object off the center table (it is lost)."""

    def __post_init__(self) -> None:
        check_reward_scheme(self.reward_scheme)
        for name in ("grasp_failure_rate", "knock_off_rate"):
            rate = getattr(self, name)
            if (
                isinstance(rate, bool)
                or not isinstance(rate, int | float)
                or not math.isfinite(rate)
                or not 0.0 <= rate <= 1.0
            ):
                raise ValueError(f"{name} must be a probability in [0, 1], got {rate!r}")
            object.__setattr__(self, name, float(rate))

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None) -> ScenarioOptions:
        """From JSON; unknown names raise a `ValueError` listing the valid ones."""
        values = values or {}
        if not isinstance(values, dict):
            raise ValueError(f"scenario options must be a JSON object, got {values!r}")
        known = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise ValueError(
                f"unknown scenario option(s) {', '.join(unknown)}; valid: {', '.join(known)}"
            )
        return cls(**values)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @property
    def realism(self) -> bool:
        """Whether any realism rate is on."""
        return self.grasp_failure_rate > 0 or self.knock_off_rate > 0
