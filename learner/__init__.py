"""The learner: the paper's deep Q-learning with interactive advice.

    from learner import DQNConfig, Trainer
    trainer = Trainer(env, DQNConfig.preset("paper"), advisor=make_advisor("oracle"), seed=7)
    trainer.run()

See docs/architecture.md ("learner: the agent") for the contract.
"""

from learner.advisors import (
    Advisor,
    AgentAdvisor,
    OracleAdvisor,
    RandomAdvisor,
    ValueAdvisor,
    make_advisor,
)
from learner.config import DQNConfig
from learner.records import EpisodeRecord, StepRecord
from learner.strategies import AdviceMoment, AdvisingStrategy, make_strategy
from learner.trainer import Trainer

__all__ = [
    "AdviceMoment",
    "AdvisingStrategy",
    "Advisor",
    "AgentAdvisor",
    "DQNConfig",
    "EpisodeRecord",
    "OracleAdvisor",
    "RandomAdvisor",
    "StepRecord",
    "Trainer",
    "ValueAdvisor",
    "make_advisor",
    "make_strategy",
]
