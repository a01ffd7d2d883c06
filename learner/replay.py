"""Experience replay that keeps every frame once.

A transition <s, a, r, s'> shares its s' with the next transition's s, so frames live
in a ring one longer than the transition ring: transition t keeps s in frame slot
t mod (C+1) and, while its episode goes on, s' in slot t+1 mod (C+1), which is free
because transition t-C has already left. When an episode ends the next reset frame
takes that slot: a terminated transition does not need s' (its target has no
bootstrap), and a truncated one does, so its s' goes into a small spare ring that grows
if truncations come faster than its size. 20,000 transitions of 64x64x3 take 246 MB.

Frames are a uint8 tensor on the training device, so the update gathers a batch without
a copy through the host and converts it to floating point inside the step.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import torch


class ReplaySample(NamedTuple):
    """A batch of transitions; `frames` holds the states, then the next states."""

    frames: torch.Tensor
    """(2B, H, W, C) uint8: rows [0, B) are s, rows [B, 2B) are s'."""
    actions: torch.Tensor
    """(B,) int64."""
    rewards: torch.Tensor
    """(B,) float32."""
    terminated: torch.Tensor
    """(B,) float32, 1.0 where s' is terminal (no bootstrap)."""

    @property
    def states(self) -> torch.Tensor:
        return self.frames[: len(self.actions)]

    @property
    def next_states(self) -> torch.Tensor:
        return self.frames[len(self.actions) :]


class ReplayMemory:
    """A ring of the last `capacity` transitions, sampled uniformly without replacement."""

    def __init__(
        self,
        capacity: int,
        frame_shape: tuple[int, ...],
        device: torch.device | str = "cpu",
        spare_frames: int = 16,
        dtype: torch.dtype = torch.uint8,
    ) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be at least 1, got {capacity}")
        self.capacity = capacity
        self.frame_shape = tuple(frame_shape)
        self.dtype = dtype
        """uint8 for images; float32 for a vector task's observations."""
        self.device = torch.device(device)
        self._ring = capacity + 1
        # empty, not zeros: pages become resident as frames arrive, and unused slots are
        # never read
        self.frames = torch.empty(
            (self._ring + spare_frames, *frame_shape), dtype=dtype, device=self.device
        )
        self.state_slot = np.zeros(capacity, dtype=np.int64)
        self.next_slot = np.zeros(capacity, dtype=np.int64)
        self.actions = np.zeros(capacity, dtype=np.int64)
        self.rewards = np.zeros(capacity, dtype=np.float32)
        self.terminated = np.zeros(capacity, dtype=np.bool_)
        self.spare_owner = np.full(spare_frames, -1, dtype=np.int64)
        self.added = 0
        """Transitions ever added; transition t lives in row t mod capacity."""
        self._spares_used = 0

    def __len__(self) -> int:
        return min(self.added, self.capacity)

    @property
    def nbytes(self) -> int:
        arrays = (self.state_slot, self.next_slot, self.actions, self.rewards, self.terminated)
        return self.frames.numel() + sum(a.nbytes for a in arrays)

    def add(
        self,
        state: np.ndarray,
        action: int,
        reward: float,
        next_state: np.ndarray,
        terminated: bool,
        truncated: bool,
    ) -> None:
        """Store one transition; `truncated` means the episode was cut and s' is needed."""
        for image in (state, next_state):
            if image.shape != self.frame_shape:
                raise ValueError(f"frames must have shape {self.frame_shape}, got {image.shape}")
        t = self.added
        row = t % self.capacity
        slot = t % self._ring
        self.frames[slot] = torch.from_numpy(np.ascontiguousarray(state))
        if terminated:
            next_slot = slot
        elif truncated:
            next_slot = self._spare_slot(t)
            self.frames[next_slot] = torch.from_numpy(np.ascontiguousarray(next_state))
        else:
            next_slot = (t + 1) % self._ring
            self.frames[next_slot] = torch.from_numpy(np.ascontiguousarray(next_state))
        self.state_slot[row] = slot
        self.next_slot[row] = next_slot
        self.actions[row] = action
        self.rewards[row] = reward
        self.terminated[row] = terminated
        self.added = t + 1

    def _spare_slot(self, t: int) -> int:
        index = self._spares_used % len(self.spare_owner)
        owner = self.spare_owner[index]
        if owner >= 0 and owner > t - self.capacity:  # still holds a live transition's s'
            index = len(self.spare_owner)
            self._grow_spares()
        self.spare_owner[index] = t
        self._spares_used = index + 1
        return self._ring + index

    def _grow_spares(self) -> None:
        """Double the spare ring; the old spares keep their slots."""
        spares = len(self.spare_owner)
        extra = torch.zeros((spares, *self.frame_shape), dtype=self.dtype, device=self.device)
        self.frames = torch.cat((self.frames, extra))
        self.spare_owner = np.concatenate((self.spare_owner, np.full(spares, -1)))

    def sample(self, batch_size: int, rng: np.random.Generator) -> ReplaySample:
        size = len(self)
        if batch_size > size:
            raise ValueError(f"cannot sample {batch_size} transitions from {size} in memory")
        rows = rng.choice(size, batch_size, replace=False)
        slots = np.concatenate((self.state_slot[rows], self.next_slot[rows]))
        index = torch.from_numpy(slots).to(self.device, non_blocking=True)
        return ReplaySample(
            frames=self.frames.index_select(0, index),
            actions=torch.from_numpy(self.actions[rows]).to(self.device),
            rewards=torch.from_numpy(self.rewards[rows]).to(self.device),
            terminated=torch.from_numpy(self.terminated[rows].astype(np.float32)).to(self.device),
        )

    def transition(self, t: int) -> tuple[np.ndarray, int, float, np.ndarray | None, bool]:
        """Transition number t (0-based, still in memory) as stored, for inspection and tests;
        s' is None when terminated."""
        if not max(0, self.added - self.capacity) <= t < self.added:
            raise IndexError(f"transition {t} is not in memory")
        row = t % self.capacity
        state = self.frames[self.state_slot[row]].cpu().numpy()
        terminated = bool(self.terminated[row])
        next_state = None if terminated else self.frames[self.next_slot[row]].cpu().numpy()
        return state, int(self.actions[row]), float(self.rewards[row]), next_state, terminated

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to continue exactly; only the filled frame slots are kept.
        They are copied out: `torch.save` writes a view's whole storage, so a slice of
        `frames` would write the full capacity (246 MB at the paper's scale) at every
        checkpoint, however few frames were filled."""
        used = min(self.added + 1, self._ring)
        return {
            "capacity": self.capacity,
            "frame_shape": list(self.frame_shape),
            "frames": self.frames[:used].to("cpu", copy=True),
            "spares": self.frames[self._ring :].to("cpu", copy=True),
            "state_slot": torch.from_numpy(self.state_slot.copy()),
            "next_slot": torch.from_numpy(self.next_slot.copy()),
            "actions": torch.from_numpy(self.actions.copy()),
            "rewards": torch.from_numpy(self.rewards.copy()),
            "terminated": torch.from_numpy(self.terminated.copy()),
            "spare_owner": torch.from_numpy(self.spare_owner.copy()),
            "added": self.added,
            "spares_used": self._spares_used,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if state["capacity"] != self.capacity or tuple(state["frame_shape"]) != self.frame_shape:
            raise ValueError(
                f"checkpoint memory holds {state['capacity']} frames of {state['frame_shape']}, "
                f"this memory {self.capacity} of {list(self.frame_shape)}"
            )
        spares = state["spares"]
        frames = torch.zeros((self._ring + len(spares), *self.frame_shape), dtype=self.dtype)
        frames[: len(state["frames"])] = state["frames"]
        frames[self._ring :] = spares
        self.frames = frames.to(self.device)
        self.state_slot = state["state_slot"].numpy().copy()
        self.next_slot = state["next_slot"].numpy().copy()
        self.actions = state["actions"].numpy().copy()
        self.rewards = state["rewards"].numpy().copy()
        self.terminated = state["terminated"].numpy().copy()
        self.spare_owner = state["spare_owner"].numpy().copy()
        self.added = int(state["added"])
        self._spares_used = int(state["spares_used"])
