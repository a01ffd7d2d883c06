import numpy as np
import pytest
import torch

from learner.replay import ReplayMemory


def frame(t: int, shape: tuple[int, ...] = (4, 4, 3)) -> np.ndarray:
    """A frame whose pixels name it."""
    return np.full(shape, t % 256, dtype=np.uint8)


def fill(memory: ReplayMemory, steps: int, episode_length: int = 7, truncate: bool = False):
    """Episodes of `episode_length` steps; frames numbered so each transition's s' = s + 1."""
    transitions = []
    t = 0
    for step in range(steps):
        last = (step + 1) % episode_length == 0
        terminated, truncated = last and not truncate, last and truncate
        state, next_state = frame(t, memory.frame_shape), frame(t + 1, memory.frame_shape)
        memory.add(state, step % 4, float(step), next_state, terminated, truncated)
        transitions.append((t, terminated))
        t += 2 if last else 1  # a reset brings a fresh frame
    return transitions


def test_memory_keeps_the_last_capacity_transitions() -> None:
    memory = ReplayMemory(10, (4, 4, 3))
    fill(memory, 25)
    assert len(memory) == 10 and memory.added == 25
    with pytest.raises(IndexError):
        memory.transition(14)
    kept_rewards = [memory.transition(t)[2] for t in range(15, 25)]
    assert kept_rewards == [float(t) for t in range(15, 25)]


@pytest.mark.parametrize("truncate", [False, True])
def test_each_transition_keeps_its_next_state_across_episodes(truncate: bool) -> None:
    memory = ReplayMemory(50, (4, 4, 3))
    numbers = fill(memory, 130, episode_length=7, truncate=truncate)
    for t in range(80, 130):
        state, action, reward, next_state, terminated = memory.transition(t)
        first_pixel, is_terminal = numbers[t]
        assert state[0, 0, 0] == first_pixel % 256 and action == t % 4 and reward == t
        assert terminated == is_terminal
        if not terminated:
            assert next_state is not None and next_state[0, 0, 0] == (first_pixel + 1) % 256


def test_frames_are_stored_once() -> None:
    memory = ReplayMemory(1000, (64, 64, 3))
    fill(memory, 1000, episode_length=250, truncate=True)
    frame_bytes = 64 * 64 * 3
    assert memory.frames.numel() * memory.frames.element_size() <= (1000 + 1 + 16) * frame_bytes
    assert memory.nbytes < 1.05 * 1000 * frame_bytes


def test_spare_frames_grow_when_truncations_are_frequent() -> None:
    memory = ReplayMemory(40, (4, 4, 3), spare_frames=2)
    numbers = fill(memory, 100, episode_length=3, truncate=True)
    for t in range(60, 100):
        next_state = memory.transition(t)[3]
        assert next_state is not None and next_state[0, 0, 0] == numbers[t][0] + 1


def test_a_frame_of_the_wrong_shape_is_refused() -> None:
    memory = ReplayMemory(10, (4, 4, 3))
    with pytest.raises(ValueError, match="4, 4, 3"):
        memory.add(frame(0, (4, 4, 4)), 0, 0.0, frame(1), False, False)
    assert len(memory) == 0


def test_sampling_is_uniform_without_replacement_and_seeded() -> None:
    memory = ReplayMemory(100, (4, 4, 3))
    fill(memory, 100)
    batch = memory.sample(64, np.random.default_rng(5))
    again = memory.sample(64, np.random.default_rng(5))
    assert torch.equal(batch.frames, again.frames) and torch.equal(batch.rewards, again.rewards)
    assert len(set(batch.rewards.tolist())) == 64
    assert batch.states.shape == (64, 4, 4, 3) and batch.next_states.shape == (64, 4, 4, 3)
    live = batch.terminated == 0
    assert torch.equal(batch.next_states[live][:, 0, 0, 0], batch.states[live][:, 0, 0, 0] + 1)
    counts = np.zeros(100)
    rng = np.random.default_rng(0)
    for _ in range(300):
        counts[memory.sample(10, rng).rewards.numpy().astype(int)] += 1
    assert counts.min() > 10 and counts.max() < 60
    with pytest.raises(ValueError, match="cannot sample"):
        memory.sample(101, rng)


def test_state_dict_round_trip_restores_the_memory() -> None:
    memory = ReplayMemory(30, (4, 4, 3), spare_frames=2)
    fill(memory, 77, episode_length=4, truncate=True)
    copy = ReplayMemory(30, (4, 4, 3))
    copy.load_state_dict(memory.state_dict())
    for t in range(47, 77):
        a, b = memory.transition(t), copy.transition(t)
        assert np.array_equal(a[0], b[0]) and a[1:3] == b[1:3] and np.array_equal(a[3], b[3])
    batch_a = memory.sample(16, np.random.default_rng(1))
    batch_b = copy.sample(16, np.random.default_rng(1))
    assert torch.equal(batch_a.frames, batch_b.frames)


def test_a_saved_memory_holds_its_filled_frames_not_its_capacity(tmp_path) -> None:
    """`torch.save` writes a view's whole storage: a memory of 20,000 paper frames saved as
    slices wrote its 246 MB at every checkpoint, however few frames it held (1.1 s a save
    on the EPYC, against 0.03 s for the 700 frames it held; every session's checkpoint
    files on disk 247 MB each)."""
    memory = ReplayMemory(2_000, (32, 32, 12))
    fill(memory, 20)
    path = tmp_path / "memory.pt"
    torch.save(memory.state_dict(), path)
    frame_bytes = 32 * 32 * 12
    assert path.stat().st_size < 100 * frame_bytes  # 21 frames and 16 spares, not 2,016
    copy = ReplayMemory(2_000, (32, 32, 12))
    copy.load_state_dict(torch.load(path, weights_only=True, mmap=True))
    for t in range(20):
        a, b = memory.transition(t), copy.transition(t)
        assert np.array_equal(a[0], b[0]) and a[1:3] == b[1:3]
