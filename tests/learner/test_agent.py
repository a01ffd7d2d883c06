import numpy as np
import pytest
import torch

from learner.agent import DQNAgent
from learner.config import DQNConfig
from learner.phase_conv import PhaseConvForward, unpack_frames
from learner.replay import ReplaySample

CPU = torch.device("cpu")


def make_batch(agent: DQNAgent, size: int = 32, seed: int = 0) -> ReplaySample:
    rng = np.random.default_rng(seed)
    images = rng.integers(0, 256, (2 * size, 64, 64, 3), dtype=np.uint8)
    images[:, :20] = 180
    frames = torch.from_numpy(np.stack([agent.encode(image) for image in images]))
    return ReplaySample(
        frames=frames,
        actions=torch.from_numpy(rng.integers(0, 4, size)),
        rewards=torch.from_numpy(rng.choice([0.0, 0.4, 1.0, -1.0, -0.01], size).astype(np.float32)),
        terminated=torch.from_numpy((rng.random(size) < 0.3).astype(np.float32)),
    )


def plain_values(agent: DQNAgent, network: torch.nn.Module, frames: torch.Tensor) -> torch.Tensor:
    images = unpack_frames(frames) if agent.config.update == "fast" else frames
    return network(images.permute(0, 3, 1, 2).float() / 255)


def expected_loss(agent: DQNAgent, batch: ReplaySample) -> float:
    """The TD loss written out, from the plain network, before the update changes it."""
    config = agent.config
    with torch.no_grad():
        q = plain_values(agent, agent.network, batch.states)
        online_next = plain_values(agent, agent.network, batch.next_states)
        if agent.target is None:
            next_value = online_next.max(1).values
        else:
            target_next = plain_values(agent, agent.target, batch.next_states)
            if config.double_dqn:
                next_value = target_next.gather(1, online_next.argmax(1, keepdim=True)).squeeze(1)
            else:
                next_value = target_next.max(1).values
        y = batch.rewards + config.gamma * (1 - batch.terminated) * next_value
        taken = q.gather(1, batch.actions.unsqueeze(1)).squeeze(1)
        if config.loss == "mse":
            return float(((taken - y) ** 2).mean())
        return float(torch.nn.functional.smooth_l1_loss(taken, y))


@pytest.mark.slow
@pytest.mark.parametrize(
    "config",
    [
        DQNConfig(update="plain"),
        DQNConfig(update="fast", precision="fp32"),
        DQNConfig(update="fast", precision="fp32", head="softmax"),
        DQNConfig.preset("modern", update="fast", precision="fp32", target_update_interval=2),
    ],
    ids=["plain", "fast", "softmax", "modern"],
)
def test_update_minimises_the_td_error_the_algorithm_defines(config: DQNConfig) -> None:
    agent = DQNAgent(config, CPU, init_seed=3)
    batch = make_batch(agent)
    losses = []
    for _ in range(4):
        expected = expected_loss(agent, batch)
        losses.append(agent.update(batch))
        assert losses[-1] == pytest.approx(expected, rel=1e-4, abs=1e-7)
    assert agent.updates == 4


def test_bfloat16_update_reports_nearly_the_float32_loss() -> None:
    agent = DQNAgent(DQNConfig(precision="bf16"), CPU, init_seed=3)
    batch = make_batch(agent)
    expected = expected_loss(agent, batch)
    assert agent.update(batch) == pytest.approx(expected, rel=0.05)


@pytest.mark.slow
def test_repeated_updates_fit_a_fixed_batch() -> None:
    # gamma 0: the targets are the rewards, a plain regression the network can overfit
    agent = DQNAgent(DQNConfig(gamma=0.0), CPU, init_seed=1)
    batch = make_batch(agent, seed=4)
    first = agent.update(batch)
    for _ in range(60):
        last = agent.update(batch)
    assert last < 0.5 * first


def test_learning_rate_zero_changes_nothing() -> None:
    agent = DQNAgent(DQNConfig(learning_rate=0.0), CPU, init_seed=1)
    before = [p.detach().clone() for p in agent.network.parameters()]
    batch = make_batch(agent)
    losses = [agent.update(batch) for _ in range(3)]
    assert losses[0] == losses[1] == losses[2]
    assert all(torch.equal(a, b) for a, b in zip(before, agent.network.parameters(), strict=True))


def test_target_network_follows_the_online_network_every_interval() -> None:
    agent = DQNAgent(DQNConfig(target_network=True, target_update_interval=3), CPU)
    assert agent.target is not None
    batch = make_batch(agent)
    agent.update(batch)
    assert not torch.equal(agent.target.out.weight, agent.network.out.weight)
    agent.update(batch)
    agent.update(batch)
    assert torch.equal(agent.target.out.weight, agent.network.out.weight)


def test_q_values_of_one_image_match_the_plain_network() -> None:
    agent = DQNAgent(DQNConfig(), CPU, init_seed=2)
    image = np.random.default_rng(0).integers(0, 256, (64, 64, 3), dtype=np.uint8)
    values = agent.q_values(image)
    with torch.no_grad():
        plain = agent.network(torch.from_numpy(image).permute(2, 0, 1)[None].float() / 255)[0]
    assert values.shape == (4,) and values.dtype == np.float32
    assert np.allclose(values, plain.numpy(), atol=0.02 * float(plain.abs().max()) + 1e-3)
    with pytest.raises(ValueError, match="uint8 images"):
        agent.q_values(image.astype(np.float32))


def test_same_init_seed_same_network() -> None:
    a, b = DQNAgent(DQNConfig(), CPU, init_seed=9), DQNAgent(DQNConfig(), CPU, init_seed=9)
    c = DQNAgent(DQNConfig(), CPU, init_seed=10)
    assert torch.equal(a.network.conv1.weight, b.network.conv1.weight)
    assert not torch.equal(a.network.conv1.weight, c.network.conv1.weight)


def assert_kernels_fresh(fast: PhaseConvForward) -> None:
    """The cached space-to-depth kernels equal kernels built now from the weights."""
    rebuilt = PhaseConvForward(fast.network, fast.dtype).kernels()
    assert all(torch.equal(a, b) for a, b in zip(fast.kernels(), rebuilt, strict=True))


def test_cached_kernels_are_reused_until_the_weights_change() -> None:
    # a step, a load_state_dict and a target sync each change weights the cache was built
    # from: a cache not rebuilt then fails assert_kernels_fresh
    config = DQNConfig(target_network=True, target_update_interval=2)
    agent = DQNAgent(config, CPU, init_seed=2)
    assert agent._fast_target is not None
    image = np.random.default_rng(0).integers(0, 256, (64, 64, 3), dtype=np.uint8)
    first = agent.q_values(image)
    builds = agent._fast.builds
    assert np.array_equal(agent.q_values(image), first) and agent._fast.builds == builds

    batch = make_batch(agent)
    agent.update(batch)
    assert agent._fast.builds == builds  # the update reused the kernels, then stepped
    assert_kernels_fresh(agent._fast)
    assert agent._fast.builds == builds + 1
    assert not np.array_equal(agent.q_values(image), first)

    target_builds = agent._fast_target.builds
    assert_kernels_fresh(agent._fast_target)
    agent.update(batch)  # the second update syncs the target network
    assert agent._fast_target.builds == target_builds
    assert_kernels_fresh(agent._fast_target)
    assert agent._fast_target.builds == target_builds + 1

    other = DQNAgent(config, CPU, init_seed=5)
    agent.load_state_dict(other.state_dict())
    assert_kernels_fresh(agent._fast)
    assert_kernels_fresh(agent._fast_target)
    assert np.array_equal(agent.q_values(image), other.q_values(image))


@pytest.mark.parametrize("precision", ["bf16", "fp32"])
def test_the_cached_kernels_gradient_is_the_rebuilt_kernels_to_the_bit(precision: str) -> None:
    agent = DQNAgent(DQNConfig(precision=precision), CPU, init_seed=4)
    fast = agent._fast
    frames = make_batch(agent, size=8).states
    grads = []
    # autograd's own derivative of the kernels' construction, against the cache's
    convs = agent.network.convs
    rebuilt = [(fast._build(conv.weight, i), conv.bias) for i, conv in enumerate(convs)]
    for weights in (rebuilt, fast.weights()):
        agent.optimizer.zero_grad()
        fast(frames, weights).square().mean().backward()
        grads.append([p.grad.clone() for p in agent.network.parameters()])  # type: ignore[union-attr]
    assert all(torch.equal(a, b) for a, b in zip(*grads, strict=True))
