"""A task whose observations are vectors (CartPole-v1, defined in the tests): its run
starts from the task's preset, its learner is the small dense network, and it trains,
checkpoints, resumes and advises like any other."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from learner.advisors import AgentAdvisor
from learner.network import DenseQNetwork, QNetwork
from learner.population import Population
from learner.run import RunSpec
from learner.trainer import Trainer
from tests.learner.conftest import Recorder

CARTPOLE = "tests.tasks.cartpole:cartpole_task"
CONFIG = {"episodes": 4, "pretraining_steps": 60, "advice_budget": 20, "batch_size": 16,
          "memory_size": 500, "max_episode_steps": 50, "torch_threads": 1}  # fmt: skip


def _run(**run: object) -> RunSpec:
    return RunSpec.from_json({"task": CARTPOLE, "config": CONFIG, **run})


def test_a_vector_tasks_run_takes_its_preset_and_the_dense_network() -> None:
    spec = _run(method="random")
    assert spec.preset == "modern" and spec.config.target_network and spec.config.double_dqn
    assert _run(preset="paper").preset == "paper"  # a run that names one keeps it
    assert RunSpec.from_json({"config": CONFIG}).preset == "paper"  # the sorting robot's
    trainer, env = spec.build()
    assert isinstance(trainer, Trainer) and isinstance(trainer.agent.network, DenseQNetwork)
    assert trainer.n_actions == 2 and trainer.memory.frames.dtype == torch.float32
    records = []
    while not trainer.done:
        records.append(trainer.step())
    assert {r.action for r in records} <= {0, 1}
    assert sum(r.advised_action is not None for r in records) == 20
    losses = [r.loss for r in records if r.loss is not None]
    assert losses and all(np.isfinite(losses))
    obs, _ = env.reset(seed=3)
    assert obs.shape == (4,) and trainer.agent.q_values(obs).shape == (2,)
    image = RunSpec.from_json({"task": "gridworld", "config": CONFIG}).build()[0]
    assert isinstance(image, Trainer) and isinstance(image.agent.network, QNetwork)


def test_a_vector_learner_resumes_exactly_and_advises_from_its_checkpoint(
    tmp_path: Path,
) -> None:
    spec = _run(method="autonomous")
    whole, _ = spec.build()
    expected = [whole.step() for _ in range(90)]
    first, _ = spec.build()
    for _ in range(70):
        first.step()
    path = tmp_path / "cartpole.pt"
    first.save_checkpoint(path, spec.to_json())
    resumed, _ = spec.build()
    assert isinstance(resumed, Trainer)
    resumed.load_checkpoint(path)
    again = [resumed.step() for _ in range(20)]
    assert [r.to_dict() for r in again] == [r.to_dict() for r in expected[70:]]

    advisor = AgentAdvisor(path)
    obs = np.array([0.01, -0.02, 0.03, 0.0], np.float32)
    assert advisor.advise(obs, {}) in (0, 1)
    assert np.allclose(advisor.q_values(obs), first.agent.q_values(obs))


def test_vector_agents_train_in_one_population_as_alone() -> None:
    specs = [_run(method="autonomous", seed=s) for s in (1, 2)]
    alone = [Recorder() for _ in specs]
    for spec, recorder in zip(specs, alone, strict=True):
        trainer, _ = spec.build([recorder])
        for _ in range(80):
            trainer.step()
    together = [Recorder() for _ in specs]
    built = [spec.build([r])[0] for spec, r in zip(specs, together, strict=True)]
    population = Population.of(built)  # type: ignore[arg-type]
    for _ in range(80):
        population.step()
    population.close()
    assert population.layout == "loop"
    for expected, recorder in zip(alone, together, strict=True):
        assert len(recorder.steps) == 80
        assert [s.to_dict() for s in recorder.steps] == [s.to_dict() for s in expected.steps]


def test_the_sb3_baseline_learns_a_vector_task_with_its_mlp_policy_and_resumes_exactly(
    tmp_path: Path,
) -> None:
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.torch_layers import FlattenExtractor

    spec = _run(method="sb3-dqn")
    whole, _ = spec.build()
    assert whole.hyperparameters["sb3_policy"] == "MlpPolicy"  # type: ignore[union-attr]
    assert isinstance(whole.model.q_net.features_extractor, FlattenExtractor)  # type: ignore[union-attr]
    expected = [whole.step() for _ in range(90)]
    training = [r for r in expected if r.stage == "train"]
    assert training and all(r.loss is not None and np.isfinite(r.loss) for r in training)
    assert {r.action for r in expected} == {0, 1}
    first, _ = spec.build()
    for _ in range(70):
        first.step()
    first.save_checkpoint(tmp_path / "sb3.pt", spec.to_json())
    resumed, _ = spec.build()
    resumed.load_checkpoint(tmp_path / "sb3.pt")
    again = [resumed.step() for _ in range(20)]
    assert [r.to_dict() for r in again] == [r.to_dict() for r in expected[70:]]
