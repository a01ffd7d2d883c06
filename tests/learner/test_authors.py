"""The `authors` preset: the Keras-style fit against a hand-computed reference, Glorot
init, updates during advice and none on an episode's final step."""

import copy

import numpy as np
import pytest
import torch

from learner import DQNConfig, Trainer, make_advisor
from learner.agent import DQNAgent
from learner.network import QNetwork
from learner.replay import ReplaySample

from .conftest import Recorder, small_config


def test_preset_has_the_authors_settings() -> None:
    config = DQNConfig.preset("authors")
    assert (config.head, config.fit, config.init) == ("softmax", "keras", "glorot")
    assert config.update_during_advice and not config.update_on_final_step
    assert config.max_episode_steps == 252 and config.keras_minibatch == 32
    assert DQNConfig.preset("authors", episodes=5).episodes == 5
    with pytest.raises(ValueError, match="fit must be one of"):
        DQNConfig(fit="sgd")


def test_glorot_init_has_zero_biases_and_glorot_bounds() -> None:
    torch.manual_seed(0)
    net = QNetwork(init="glorot")
    for layer in (*net.convs, net.dense, net.out):
        assert torch.count_nonzero(layer.bias) == 0
        fan_in = layer.weight[0].numel()
        fan_out = layer.weight.shape[0] * layer.weight[0, 0].numel()
        bound = float(np.sqrt(6.0 / (fan_in + fan_out)))
        assert layer.weight.abs().max() <= bound
        assert layer.weight.abs().max() > 0.9 * bound  # uniform over the whole range
    assert torch.count_nonzero(QNetwork().dense.bias) > 0  # PyTorch's default differs


def test_keras_fit_against_a_hand_computed_reference() -> None:
    """Batch of 4, minibatches of 2, plain float32 path, plain SGD-sized RMSprop step:
    the reference builds each target row by hand and takes the mean of squared errors
    over the minibatch's 2 x 4 outputs, in the order the same RNG shuffles."""
    config = DQNConfig.preset(
        "authors", batch_size=4, keras_minibatch=2, pretraining_steps=4, update="plain",
        device="cpu", learning_rate=1e-2,
    )  # fmt: skip
    agent = DQNAgent(config, torch.device("cpu"), init_seed=3)
    reference = copy.deepcopy(agent.network)
    gen = torch.Generator().manual_seed(1)
    frames = torch.randint(0, 256, (8, 64, 64, 3), dtype=torch.uint8, generator=gen)
    batch = ReplaySample(
        frames=frames,
        actions=torch.tensor([0, 3, 1, 3]),
        rewards=torch.tensor([0.4, -0.01, 1.0, 0.0]),
        terminated=torch.tensor([0.0, 0.0, 1.0, 0.0]),
    )
    loss = agent.update(batch, np.random.default_rng(42))

    def images(rows: torch.Tensor) -> torch.Tensor:
        return rows.permute(0, 3, 1, 2).float() / 255.0

    with torch.no_grad():
        predicted = reference(images(frames[:4])).numpy()
        next_q = reference(images(frames[4:])).numpy()
    targets = predicted.copy()
    for i in range(4):
        action, reward = int(batch.actions[i]), float(batch.rewards[i])
        done = bool(batch.terminated[i])
        targets[i, action] = reward if done else reward + 0.9 * next_q[i].max()
    from learner.optim import RMSprop

    optimizer = RMSprop(reference.parameters(), 1e-2, 0.9, 1e-7)
    order = np.random.default_rng(42).permutation(4)
    losses = []
    for part in (order[:2], order[2:]):
        out = reference(images(frames[torch.from_numpy(part)]))
        errors = out - torch.from_numpy(targets[part])
        mse = (errors**2).sum() / errors.numel()
        optimizer.zero_grad()
        mse.backward()
        optimizer.step()
        losses.append(float(mse.detach()))
    assert loss == pytest.approx(np.mean(losses), rel=1e-5)
    for mine, theirs in zip(agent.network.parameters(), reference.parameters(), strict=True):
        torch.testing.assert_close(mine, theirs, rtol=1e-5, atol=1e-6)
    assert agent.updates == 2  # one optimizer step per minibatch


def test_keras_fit_moves_untaken_outputs_only_through_shared_weights() -> None:
    """With a TD fit the loss ignores the untaken outputs; with the Keras fit they are
    pulled to their own predictions, so a batch whose taken targets equal the predictions
    has zero loss and leaves the network unchanged."""
    config = DQNConfig.preset("authors", batch_size=4, keras_minibatch=4, pretraining_steps=4,
                              update="plain", device="cpu", gamma=0.0)  # fmt: skip
    agent = DQNAgent(config, torch.device("cpu"), init_seed=0)
    frames = torch.randint(0, 256, (8, 64, 64, 3), dtype=torch.uint8)
    with torch.no_grad():
        q = agent.network(frames[:4].permute(0, 3, 1, 2).float() / 255.0)
    actions = torch.tensor([0, 1, 2, 3])
    batch = ReplaySample(frames, actions, q[torch.arange(4), actions].float(), torch.ones(4))
    before = [p.clone() for p in agent.network.parameters()]
    # One minibatch of the whole batch: its forward pass has the shape of the one above, so
    # its outputs are the same bits (minibatches of 2 may take other CPU kernels, and
    # RMSprop turns even a 1e-9 loss into steps of the learning rate's size).
    assert agent.update(batch, np.random.default_rng(0)) == pytest.approx(0.0, abs=1e-12)
    for a, b in zip(before, agent.network.parameters(), strict=True):
        torch.testing.assert_close(a, b)


@pytest.mark.slow
def test_updates_during_advice_and_not_on_final_steps(make_env) -> None:
    config = small_config(**{
        k: v for k, v in DQNConfig.preset("authors").to_dict().items()
        if k in ("head", "fit", "init", "update_during_advice", "update_on_final_step")
    })  # fmt: skip
    recorder = Recorder()
    trainer = Trainer(make_env(), config, advisor=make_advisor("oracle", seed=0), seed=1,
                      callbacks=[recorder])  # fmt: skip
    trainer.run()
    steps = recorder.steps
    advised = [s for s in steps if s.stage == "pretrain" and s.action_source == "advisor"]
    assert len(advised) == config.advice_budget
    for s in steps:
        final = s.terminated or s.truncated
        if (s.stage == "pretrain" and s.action_source == "random") or final:
            assert s.loss is None, s
        elif s.stage == "pretrain":
            assert s.loss is not None  # the memory holds a batch long before the advice
        else:
            assert s.loss is not None
    updates = sum(s.loss is not None for s in steps)
    assert trainer.epsilon.value == pytest.approx(
        config.epsilon_start * config.epsilon_decay**updates
    )
    # the paper's loop: no update in pretraining, one after every training step
    recorder = Recorder()
    Trainer(make_env(), small_config(), advisor=make_advisor("oracle", seed=0), seed=1,
            callbacks=[recorder]).run()  # fmt: skip
    for s in recorder.steps:
        assert (s.loss is None) == (s.stage != "train")
