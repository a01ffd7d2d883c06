"""Every hyperparameter of the learner, in one JSON-able dataclass.

The server stores a config per session and accepts overrides from a REST body, so
`from_dict` checks every field and raises a `ValueError` that names the field and
its valid values instead of failing somewhere deep in a training run.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Any, Literal

from learner.docstrings import field_docstrings
from learner.fields import AtLeast, FieldError, Needs, bounded, build, checked

Head = Literal["linear", "softmax"]
Loss = Literal["mse", "huber"]
Optimizer = Literal["rmsprop", "adam"]
UpdateImpl = Literal["fast", "plain"]
Precision = Literal["auto", "bf16", "fp32"]
ConvKernel = Literal["auto", "none", "avx512bf16:1-3", "avx2:1-3", "avx512bf16", "avx2"]
Fit = Literal["td", "keras"]
Init = Literal["torch", "glorot"]

PRESETS = ("paper", "modern", "authors")
Preset = Literal["paper", "modern", "authors"]
AUTHORS = {
    "head": "softmax",
    "fit": "keras",
    "init": "glorot",
    "update_during_advice": True,
    "update_on_final_step": False,
    "max_episode_steps": 252,
}
"""The `authors` preset: what their Keras scripts did beyond the paper's text (each field's
docstring says where it comes from; shared/reference/README.md, "The learner as coded")."""
PRESET_FIELDS: dict[str, dict[str, Any]] = {
    "paper": {},
    "modern": {"target_network": True, "double_dqn": True, "loss": "huber", "grad_clip_norm": 10.0},
    "authors": AUTHORS,
}
"""The fields each preset sets; the rest keep their defaults (the paper's)."""


@dataclass(frozen=True)
@checked(
    AtLeast("pretraining_steps", "batch_size", "the first update samples a full batch"),
    AtLeast("memory_size", "batch_size", "the memory holds at least one batch"),
    Needs("double_dqn", "target_network"),
)
class DQNConfig:
    """The paper's deep Q-learning (Algorithms 1 and 2) and the few choices it leaves open.

    Defaults are the `paper` preset: the paper's numbers, and the authors' public Keras
    code (IthanMoreira/DeppRL) where the paper is silent (no target network, MSE, RMSprop).
    """

    episodes: int = bounded(300, 1, 100_000, role="scale")
    """Training episodes (the paper's 300); pretraining episodes are not counted."""
    max_episode_steps: int = bounded(250, 1, 10_000)
    """An episode is truncated after this many steps (the paper's 250)."""
    pretraining_steps: int = bounded(1000, 0, 10_000_000)
    """Actions taken to fill the memory before training (Algorithm 1): all random for
    the autonomous agent; the last `advice_budget` of them advised under early advising."""
    advice_budget: int = bounded(100, 0, 1_000_000, role="treatment")
    """Advised actions a strategy may use when none is given explicitly (the paper's 100)."""
    batch_size: int = bounded(128, 1, 4096)
    """Transitions <s, a, r, s'> sampled from memory for each update (the paper's 128)."""
    learning_rate: float = bounded(1e-3, 0.0, 10.0)
    """Optimizer step size (the paper's 1e-3)."""
    gamma: float = bounded(0.9, 0.0, 1.0)
    """Discount factor (the paper's 0.9)."""
    epsilon_start: float = bounded(1.0, 0.0, 1.0)
    """Exploration rate at the first training step (the paper's 1.0)."""
    epsilon_decay: float = bounded(0.9995, 0.0, 1.0, exclusive_minimum=True)
    """Epsilon is multiplied by this after every training update (the paper's 0.9995,
    which reaches 1 % after about 9,200 updates: near episode 150 in the paper)."""
    epsilon_min: float = bounded(0.01, 0.0, 1.0)
    """Floor of epsilon (1 %)."""
    memory_size: int = bounded(20_000, 1, 10_000_000)
    """Replay memory capacity in transitions (not in the paper; the authors' code keeps
    20,000). Frames are stored once as uint8: about 246 MB at 64x64x3."""
    head: Head = bounded("linear")
    """Output layer: `linear` Q-values (default), or the paper's `softmax`. A softmax
    squeezes the outputs into [0, 1] summing to 1, so they cannot be Q-values whose
    returns reach 3; the authors used it, we offer it to reproduce them."""
    loss: Loss = bounded("mse")
    """TD loss on the taken action: `mse` (the authors' Keras code) or `huber`."""
    optimizer: Optimizer = bounded("rmsprop")
    """`rmsprop` (the authors' code) or `adam`."""
    rmsprop_alpha: float = bounded(0.9, 0.0, 1.0)
    """RMSprop's moving-average factor; 0.9 is Keras' `rho`, which the authors used."""
    optimizer_eps: float = bounded(1e-7, 0.0, 1.0, exclusive_minimum=True)
    """Optimizer epsilon; 1e-7 is Keras' default."""
    target_network: bool = bounded(False)
    """Compute targets with a periodically synchronised copy of the network."""
    target_update_interval: int = bounded(500, 1, 10_000_000)
    """Updates between target-network synchronisations (when `target_network`)."""
    double_dqn: bool = bounded(False)
    """Double DQN: the online network picks the next action, the target network values it
    (needs `target_network`)."""
    grad_clip_norm: float | None = bounded(None, 0.0, 1e9, exclusive_minimum=True)
    """Clip the gradient's global L2 norm to this value; None: no clipping."""
    fit: Fit = bounded("td")
    """How a sampled batch is fitted. `td`: one gradient step on the TD error of the taken
    actions. `keras`: as the authors' `Deep_NN.py:97-110` did with Keras' `fit`: targets for
    all outputs, the taken action's r + gamma max Q(s') and the others the network's own
    predictions (computed once, before the steps), MSE over all outputs, in minibatches of
    `keras_minibatch` (Keras' default 32: four gradient steps on a batch of 128, in a
    shuffled order, as `fit(shuffle=True)` does)."""
    keras_minibatch: int = bounded(32, 1, 4096)
    """Minibatch size of `fit="keras"` (Keras' default batch size, which the authors kept)."""
    init: Init = bounded("torch")
    """Initial weights: `torch` (PyTorch's default, Kaiming-uniform) or `glorot` (Keras'
    default that the authors' model got: Glorot-uniform weights, zero biases)."""
    update_during_advice: bool = bounded(False)
    """Also update after each advised pretraining step (the authors' agent-advised script,
    78a15b8:199-253, trains after every one of its advised steps; epsilon decays with each
    such update, as their `entrenar` does). Without it pretraining never updates."""
    update_on_final_step: bool = bounded(True)
    """Update after an episode's final step too. The authors' loop breaks out of the episode
    before training (`Deep_NN.py:238-252`), so their final steps never update (False)."""
    update: UpdateImpl = bounded("fast", role="numerics")
    """`fast`: convolution and pooling fused by space-to-depth, bfloat16 convolutions,
    uint8 frames converted inside the step (same network, same function); `plain`: the
    textbook float32 path, kept to show that the fast update learns the same."""
    precision: Precision = bounded("auto", role="numerics")
    """Convolution precision of the fast update: `bf16` where the device supports it
    natively (`auto`), else `fp32`. Dense layers and the loss stay float32."""
    conv_kernel: ConvKernel = bounded("auto", role="numerics")
    """The fast update's convolutions on the CPU: `none` (PyTorch), or our compiled kernels
    (`learner.conv_kernel`), `avx512bf16` (bfloat16 values, for `bf16`) or `avx2` (float32
    FMA, for `fp32`), named with the layers they compute: `avx2:1-3` all three, a bare
    `avx2` the first alone (the rest in PyTorch); the same function in another float
    order. `auto`: the variant for the precision that runs here, for all three layers,
    where `IDEEPRL_CONV_KERNEL=on`, else `none`."""
    device: str = bounded(
        "auto", role="numerics", max_length=16, pattern=r"auto|cpu|cuda(:[0-9]+)?"
    )
    """`auto` (CUDA when available, else CPU), `cpu`, `cuda` or `cuda:N`."""
    torch_threads: int = bounded(0, 0, 256, role="numerics")
    """Torch CPU threads for this process; 0 picks half the cores (1 to 4), leaving the
    rest to the simulator and other workers: 1 on a 2-core machine. Results are
    bit-identical only for the same thread count."""

    @classmethod
    def preset(cls, name: str, **overrides: Any) -> DQNConfig:
        """`paper` (the default fields), `modern` (target network, Double DQN, Huber loss,
        gradient clipping) or `authors` (what the authors' Keras code did: softmax head
        fitted the Keras way, Glorot init, updates during advice and not on an episode's
        final step, the 252-step limit of their `time > 250`); keyword overrides are checked
        like `from_dict`."""
        if name not in PRESET_FIELDS:
            raise ValueError(f"unknown preset {name!r}; valid presets: {', '.join(PRESETS)}")
        return cls.from_dict({**PRESET_FIELDS[name], **overrides})

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> DQNConfig:
        """Build from JSON values, each checked against its declaration; an unknown or
        out-of-range field raises a `FieldError` (a `ValueError`) naming it."""
        return build(cls, values)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def replace(self, **changes: Any) -> DQNConfig:
        """This config with some fields changed, each checked like `from_dict`'s."""
        unknown = sorted(set(changes) - {f.name for f in dataclasses.fields(self)})
        if unknown:
            raise FieldError(unknown[0], f"unknown field {unknown[0]}")
        return dataclasses.replace(self, **changes)


PER_AGENT_FIELDS = ("advice_budget", "episodes")
"""Config fields agents computed together may differ in: they decide how long an agent
runs and how much advice it may get, never what its network computes (an unadvised run's
budget is 0, an advised one's is not, and they still share a population)."""


@functools.lru_cache(maxsize=256)
def shared_config(config: DQNConfig) -> DQNConfig:
    """What agents computed together must share: `config` without `PER_AGENT_FIELDS`.
    Cached (configs are frozen): a population checks its agents' configs at every batched
    forward pass, and building a validated config costs about a millisecond."""
    return config.replace(advice_budget=0, episodes=1)


def field_docs() -> dict[str, str]:
    """Each field's docstring, for help texts and the server's API documentation."""
    return field_docstrings(DQNConfig)
