"""The learner: the paper's deep Q-learning with interactive advice.

    from learner import DQNConfig, Trainer
    trainer = Trainer(env, DQNConfig.preset("paper"), advisor=make_advisor("oracle"), seed=7)
    trainer.run()

See docs/architecture.md ("learner: the agent") for the contract. Torch is imported only
when a name that computes is first asked for (`Trainer`), as `sim` does for PyBullet, so
the server and the analysis can use the config, records, advisors and strategies (and
their types) without it.
"""

from typing import TYPE_CHECKING, Any

from learner.advisors import (
    Advisor,
    AgentAdvisor,
    OracleAdvisor,
    RandomAdvisor,
    ValueAdvisor,
    make_advisor,
)
from learner.config import DQNConfig
from learner.fitted import FittedAdvisor, FittedModel
from learner.records import EpisodeRecord, StepRecord
from learner.strategies import AdviceMoment, AdvisingStrategy, make_strategy

if TYPE_CHECKING:
    from learner.population import Member, Population
    from learner.trainer import Trainer


def __getattr__(name: str) -> Any:
    if name == "Trainer":
        from learner.trainer import Trainer

        return Trainer
    if name in ("Population", "Member"):
        from learner import population

        return getattr(population, name)
    raise AttributeError(f"module 'learner' has no attribute {name!r}")


__all__ = [
    "AdviceMoment",
    "AdvisingStrategy",
    "Advisor",
    "AgentAdvisor",
    "DQNConfig",
    "EpisodeRecord",
    "FittedAdvisor",
    "FittedModel",
    "Member",
    "OracleAdvisor",
    "Population",
    "RandomAdvisor",
    "StepRecord",
    "Trainer",
    "ValueAdvisor",
    "make_advisor",
    "make_strategy",
]
