import dataclasses
import json

import pytest

from learner import DQNConfig
from learner.config import field_docs
from learner.fields import FieldError, checked


def test_paper_preset_has_the_papers_hyperparameters() -> None:
    config = DQNConfig.preset("paper")
    assert config == DQNConfig()
    assert (config.episodes, config.max_episode_steps, config.pretraining_steps) == (300, 250, 1000)
    assert (config.advice_budget, config.batch_size, config.memory_size) == (100, 128, 20_000)
    assert (config.learning_rate, config.gamma) == (1e-3, 0.9)
    assert (config.epsilon_start, config.epsilon_decay, config.epsilon_min) == (1.0, 0.9995, 0.01)
    assert (config.head, config.loss, config.target_network, config.device) == (
        "linear", "mse", False, "auto",
    )  # fmt: skip


def test_modern_preset_adds_target_network_double_dqn_huber_and_clipping() -> None:
    modern = DQNConfig.preset("modern")
    assert modern.target_network and modern.double_dqn
    assert modern.loss == "huber" and modern.grad_clip_norm is not None
    changed = {k for k, v in modern.to_dict().items() if DQNConfig().to_dict()[k] != v}
    assert changed == {"target_network", "double_dqn", "loss", "grad_clip_norm"}


def test_config_survives_json_and_accepts_overrides() -> None:
    config = DQNConfig.preset("modern", episodes=20, head="softmax")
    again = DQNConfig.from_dict(json.loads(json.dumps(config.to_dict())))
    assert again == config and again.episodes == 20 and again.head == "softmax"
    assert config.replace(learning_rate=0).learning_rate == 0.0


def test_every_field_is_documented() -> None:
    docs = field_docs()
    assert set(docs) == {f.name for f in dataclasses.fields(DQNConfig)}
    assert all(len(text) > 10 for text in docs.values())


@pytest.mark.parametrize(
    ("values", "words"),
    [
        ({"epsilon": 0.5}, ["epsilon", "valid fields", "epsilon_decay"]),
        ({"head": "sigmoid"}, ["head", '"linear"', '"softmax"']),
        ({"loss": "l1"}, ["loss", '"mse"', '"huber"']),
        ({"episodes": "300"}, ["episodes", "an integer from 1 to 100000"]),
        ({"episodes": True}, ["episodes", "an integer"]),
        ({"episodes": 0}, ["episodes", "from 1 to"]),
        ({"gamma": 1.5}, ["gamma", "a number from 0 to 1"]),
        ({"device": "gpu"}, ["device", "cuda"]),
        ({"double_dqn": True}, ["double_dqn", "target_network"]),
        ({"pretraining_steps": 64}, ["pretraining_steps", "batch_size"]),
    ],
)
def test_bad_fields_raise_a_message_naming_the_field_and_valid_values(
    values: dict[str, object], words: list[str]
) -> None:
    with pytest.raises(ValueError) as error:
        DQNConfig.from_dict(values)
    for word in words:
        assert word in str(error.value)


@pytest.mark.parametrize(
    "make",
    [
        lambda: DQNConfig(pretraining_steps=64),  # made directly
        lambda: DQNConfig().replace(memory_size=16, pretraining_steps=16, batch_size=32),
        lambda: dataclasses.replace(DQNConfig(), double_dqn=True),
        lambda: DQNConfig(batch_size=0),  # a field alone
        lambda: DQNConfig().replace(device="gpu"),
        lambda: DQNConfig().replace(colour="red"),  # not a field
    ],
)
def test_every_way_of_making_a_config_checks_its_fields_and_rules(make: object) -> None:
    with pytest.raises(FieldError):
        make()  # type: ignore[operator]


def test_a_checked_class_declares_its_rules_and_writes_no_post_init() -> None:
    assert [type(rule).__name__ for rule in DQNConfig.__rules__] == ["AtLeast", "AtLeast", "Needs"]
    with pytest.raises(TypeError, match="declare rules"):

        @dataclasses.dataclass(frozen=True)
        @checked()
        class Own:
            def __post_init__(self) -> None: ...


def test_unknown_preset_names_the_valid_ones() -> None:
    with pytest.raises(ValueError, match="paper, modern"):
        DQNConfig.preset("fancy")
