"""Agents trained together are the same agents as alone (SPEC 5, "Populations")."""

import hashlib

import gymnasium as gym
import numpy as np
import pytest
import torch

from learner import Trainer, make_advisor, make_strategy
from learner.population import Member, Population, resolve_layout
from learner.stacked import StackedAgents
from tests.learner.conftest import Recorder, small_config

Q_TOLERANCE = 1e-2
"""Relative difference allowed between an agent's Q-values alone and in a population with
grouped convolutions (the same function, another float order; bfloat16 convolutions)."""


class Hashing(gym.Wrapper):
    """Keeps a hash of every observation the agent is shown."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.hashes: list[str] = []

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self.hashes.append(hashlib.sha1(obs.tobytes()).hexdigest())
        return obs, info

    def step(self, action):
        result = self.env.step(action)
        self.hashes.append(hashlib.sha1(result[0].tobytes()).hexdigest())
        return result


def agents(make_env, checkpoint) -> list[dict]:
    """Four agents of one config, with different methods and reward schemes."""
    return [
        {"seed": 1, "env": {}, "advisor": None, "strategy": None},
        {
            "seed": 2,
            "env": {"reward_scheme": "authors-interactive"},
            "advisor": ("oracle", {"seed": 2, "error_rate": 0.2}),
            "strategy": ("early", {}),
        },
        {
            "seed": 3,
            "env": {"reward_scheme": "authors-autonomous", "grasp_failure_rate": 0.1},
            "advisor": ("random", {"seed": 3}),
            "strategy": ("alternating", {"interval": 3}),
        },
        {
            "seed": 4,
            "env": {},
            "advisor": ("agent", {"checkpoint": checkpoint}),
            "strategy": ("early", {}),
        },
    ]


def build(make_env, spec: dict, recorder: Recorder) -> Member:
    advisor = make_advisor(spec["advisor"][0], **spec["advisor"][1]) if spec["advisor"] else None
    strategy = None
    if spec["strategy"]:
        strategy = make_strategy(spec["strategy"][0], 10, **spec["strategy"][1])
    env = Hashing(make_env(max_episode_steps=30, **spec["env"]))
    return Member(env, spec["seed"], advisor, strategy, [recorder])


@pytest.fixture(scope="module")
def advisor_checkpoint(tmp_path_factory) -> str:
    """A learner that has made a few updates, to advise as the agent advisor."""
    import sim

    env = sim.SortingEnv(motion="fast", max_episode_steps=30)
    trainer = Trainer(env, small_config(), seed=9)
    for _ in range(70):
        trainer.step()
    path = tmp_path_factory.mktemp("advisor") / "advisor.pt"
    trainer.save_checkpoint(path, memory=False)
    env.close()
    return str(path)


@pytest.mark.slow
def test_an_agent_in_a_mixed_population_takes_the_course_it_takes_alone(
    make_env, advisor_checkpoint
) -> None:
    config = small_config()
    steps = config.pretraining_steps + 15
    specs = agents(make_env, advisor_checkpoint)
    alone = []
    for spec in specs:
        recorder = Recorder()
        member = build(make_env, spec, recorder)
        trainer = Trainer(
            member.env, config, member.advisor, member.strategy, member.seed, [recorder]
        )
        for _ in range(steps):
            trainer.step()
        alone.append((recorder, member.env.hashes))
    recorders = [Recorder() for _ in specs]
    members = [build(make_env, s, r) for s, r in zip(specs, recorders, strict=True)]
    # two workers, each updating two agents stacked together
    population = Population(config, members, layout="stacked", workers=2)
    for _ in range(steps):
        assert sorted(population.step()) == [0, 1, 2, 3]
    population.close()
    assert population.numerics()["workers"] == 2
    for (expected, hashes), recorder, member in zip(alone, recorders, members, strict=True):
        # every column, Q-values and losses included: the stacked layout computes each
        # agent's values with the agent's own kernels, in its own float order
        assert [s.to_dict() for s in recorder.steps] == [s.to_dict() for s in expected.steps]
        assert [e.to_dict() for e in recorder.episodes] == [e.to_dict() for e in expected.episodes]
        assert member.env.hashes == hashes and len(hashes) > steps
    # each agent kept its own method and reward scheme
    advised = [[s.global_step for s in r.steps if s.advised_action is not None] for r in recorders]
    assert advised[0] == []
    assert advised[1] == advised[3] == list(range(51, 61))
    assert advised[2] == [61, 64, 67, 70, 73]
    penalties = [{s.reward for s in r.steps if s.reward not in (0.4, 1.0, -1.0)} for r in recorders]
    assert penalties[0] <= {0.0, -0.01} and penalties[1] == {-0.01}  # paper, authors-interactive
    assert min(penalties[2]) < -0.01  # authors-autonomous: a growing penalty
    early = [{s.reward for s in r.steps if s.episode_step <= 18} for r in recorders]
    assert -0.01 not in early[0] | early[2] and -0.01 in early[1]


def test_the_loop_fallback_is_each_trainer_alone_bit_for_bit(make_env) -> None:
    config = small_config(episodes=2)
    seeds = (5, 6)
    alone = []
    for seed in seeds:
        recorder = Recorder()
        Trainer(make_env(max_episode_steps=30), config, seed=seed, callbacks=[recorder]).run()
        alone.append([s.to_dict() for s in recorder.steps])
    recorders = [Recorder() for _ in seeds]
    members = [
        Member(make_env(max_episode_steps=30), s, callbacks=[r])
        for s, r in zip(seeds, recorders, strict=True)
    ]
    population = Population(config, members, layout="loop")
    population.run()
    assert [[s.to_dict() for s in r.steps] for r in recorders] == alone
    cpu, cuda = torch.device("cpu"), torch.device("cuda")
    assert resolve_layout("auto", config, cpu) == "stacked-actions"
    assert resolve_layout("auto", config, cuda) == "stacked"
    assert resolve_layout("auto", small_config(update="plain"), cuda) == "loop"
    with pytest.raises(ValueError, match="layout='loop'"):
        resolve_layout("stacked", small_config(update="plain"), cpu)
    with pytest.raises(ValueError, match="layout must be one of"):
        resolve_layout("vectorised", config, cpu)


def test_grouped_convolutions_compute_the_same_values_and_update() -> None:
    """The stacked layout's two ways to run the convolutions, against each agent alone."""
    config = small_config(
        batch_size=8, target_network=True, double_dqn=True, loss="huber", grad_clip_norm=0.05
    )  # a norm small enough to clip every update: per agent, or the weights differ
    from learner.agent import DQNAgent
    from learner.replay import ReplayMemory

    device = torch.device("cpu")
    rng = np.random.default_rng(0)
    images = rng.integers(0, 256, (40, 64, 64, 3), dtype=np.uint8)
    results = {}
    for conv in ("loop", "grouped", "alone"):
        agents = [DQNAgent(config, device, init_seed=seed) for seed in (1, 2, 3)]
        memory = ReplayMemory(64, agents[0].frame_shape)
        for t in range(39):
            memory.add(agents[0].encode(images[t]), t % 4, 0.4 * (t % 3 == 0),
                       agents[0].encode(images[t + 1]), t % 9 == 8, False)  # fmt: skip
        batches = [memory.sample(8, np.random.default_rng(k)) for k in range(3)]
        if conv == "alone":
            q = np.stack([a.q_values(images[k]) for k, a in enumerate(agents)])
            losses = [a.update(b) for a, b in zip(agents, batches, strict=True)]
        else:
            stacked = StackedAgents(agents, conv)  # type: ignore[arg-type]
            q = stacked.q_values(list(images[:3]), conv)  # type: ignore[arg-type]
            losses = stacked.update(batches, [np.random.default_rng(0)] * 3)
        weights = [a.network.dense.weight.detach().clone() for a in agents]
        results[conv] = (q, losses, weights)
    q, losses, weights = results["alone"]
    for conv in ("loop", "grouped"):
        np.testing.assert_allclose(results[conv][0], q, rtol=Q_TOLERANCE, atol=1e-4)
        np.testing.assert_allclose(results[conv][1], losses, rtol=1e-2)
        for mine, theirs in zip(results[conv][2], weights, strict=True):
            torch.testing.assert_close(mine, theirs, rtol=1e-3, atol=1e-5)


@pytest.mark.slow
def test_float32_parameters_after_50_updates_agree_alone_and_in_a_population(make_env) -> None:
    config = small_config(precision="fp32", episodes=10)
    seeds = (7, 8)

    class Snapshot:
        def __init__(self, trainer: Trainer) -> None:
            self.trainer, self.params = trainer, None

        def on_step(self, record) -> None:
            if self.params is None and self.trainer.agent.updates == 50:
                self.params = [p.detach().clone() for p in self.trainer.agent.network.parameters()]

    alone = []
    for seed in seeds:
        trainer = Trainer(make_env(max_episode_steps=30), config, seed=seed)
        while trainer.agent.updates < 50:
            trainer.step()
        alone.append([p.detach().clone() for p in trainer.agent.network.parameters()])
    members = [Member(make_env(max_episode_steps=30), s) for s in seeds]
    population = Population(config, members, layout="stacked")
    snapshots = [Snapshot(t) for t in population.trainers]
    for trainer, snapshot in zip(population.trainers, snapshots, strict=True):
        trainer.callbacks.append(snapshot)
    while any(s.params is None for s in snapshots):
        population.step()
    for snapshot, expected in zip(snapshots, alone, strict=True):
        for mine, theirs in zip(snapshot.params, expected, strict=True):
            assert (mine - theirs).norm() <= 1e-3 * theirs.norm()


@pytest.mark.slow
def test_a_resumed_population_matches_an_uninterrupted_one(make_env, tmp_path) -> None:
    config = small_config(episodes=2)
    seeds = (11, 12)

    def population(recorders) -> Population:
        members = [
            Member(make_env(max_episode_steps=30), s, make_advisor("oracle", seed=s), callbacks=[r])
            for s, r in zip(seeds, recorders, strict=True)
        ]
        return Population(config, members, layout="stacked")

    uninterrupted = [Recorder() for _ in seeds]
    population(uninterrupted).run()

    first = [Recorder() for _ in seeds]
    killed = population(first)
    for _ in range(75):  # pretraining, and some updates
        killed.step()
    paths = [tmp_path / f"agent{i}.pt" for i in range(2)]
    for i, path in enumerate(paths):
        killed.save_checkpoint(i, path, {"study": "x"})
    del killed
    second = [Recorder() for _ in seeds]
    resumed = population(second)
    for i, path in enumerate(paths):
        resumed.load_checkpoint(i, path)
    resumed.run()
    for a, b, c in zip(uninterrupted, first, second, strict=True):
        assert [s.to_dict() for s in b.steps + c.steps] == [s.to_dict() for s in a.steps]
        assert [e.to_dict() for e in b.episodes + c.episodes] == [e.to_dict() for e in a.episodes]

    from learner.checkpoint import read_checkpoint

    metadata = read_checkpoint(paths[1])["metadata"]
    assert metadata["study"] == "x"
    assert metadata["population"] == {**resumed.numerics(1), "population_index": 1}
    assert metadata["population"]["population_size"] == 2
    assert metadata["population"]["layout"] == "stacked"


def test_checkpoints_pass_between_a_population_and_a_plain_trainer(make_env, tmp_path) -> None:
    config = small_config(episodes=2)
    reference = Recorder()
    population = Population(
        config, [Member(make_env(max_episode_steps=30), 3, callbacks=[reference])], layout="loop"
    )
    for _ in range(70):
        population.step()
    population.save_checkpoint(0, tmp_path / "agent.pt")
    for _ in range(10):
        population.step()
    recorder = Recorder()
    trainer = Trainer(make_env(max_episode_steps=30), config, seed=0, callbacks=[recorder])
    trainer.load_checkpoint(tmp_path / "agent.pt")
    for _ in range(10):
        trainer.step()
    assert [s.to_dict() for s in recorder.steps] == [s.to_dict() for s in reference.steps[70:]]
    trainer.save_checkpoint(tmp_path / "trainer.pt")
    again = Recorder()
    back = Population(config, [Member(make_env(max_episode_steps=30), 0, callbacks=[again])])
    back.load_checkpoint(0, tmp_path / "trainer.pt")
    assert back.trainers[0].global_step == 80
    back.step()
    assert again.steps[0].global_step == 81


def test_an_agent_that_finishes_leaves_and_the_others_go_on(make_env) -> None:
    class StopAt:
        def __init__(self, step: int) -> None:
            self.step = step

        def on_step(self, record) -> bool:
            return record.global_step < self.step

    config = small_config(episodes=1)
    members = [
        Member(make_env(max_episode_steps=30), 1, callbacks=[StopAt(65)]),
        Member(make_env(max_episode_steps=30), 2),
    ]
    population = Population(config, members)
    for _ in range(65):
        population.step()
    assert population.active == [1]
    assert list(population.step()) == [1]
    population.run()
    assert population.done and population.trainers[0].global_step == 65
    assert population.trainers[1].episodes_done["train"] == 1
    with pytest.raises(RuntimeError, match="done"):
        population.step()
    assert population.numerics()["population_size"] == 2


def test_trainers_built_elsewhere_join_if_they_share_the_learner_config(make_env) -> None:
    """A batch builds each agent's trainer from its session: an unadvised run's budget is 0,
    an advised one's is not, and runs may differ in length; anything else the network
    computes with must be the same."""
    config = small_config(episodes=1)
    advisor = make_advisor("random", seed=3)
    alone = Trainer(make_env(), config.replace(advice_budget=0), seed=1)
    advised = Trainer(make_env(), config.replace(episodes=2), advisor, "early", seed=2)
    population = Population.of([alone, advised])
    assert population.trainers == [alone, advised] and population.size == 2
    population.step()
    other = Trainer(make_env(), config.replace(batch_size=32), seed=4)
    with pytest.raises(ValueError, match="share one learner configuration"):
        Population.of([alone, other])
    with pytest.raises(ValueError, match="at least one member"):
        Population.of([])


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_a_population_computes_on_cuda_when_present(make_env) -> None:
    config = small_config(device="cuda")
    alone = Recorder()
    trainer = Trainer(
        make_env(max_episode_steps=30),
        config,
        make_advisor("oracle", seed=1),
        seed=1,
        callbacks=[alone],
    )
    recorder = Recorder()
    member = Member(
        make_env(max_episode_steps=30), 1, make_advisor("oracle", seed=1), callbacks=[recorder]
    )
    population = Population(config, [member, Member(make_env(max_episode_steps=30), 2)])
    assert population.layout == "stacked" and population.numerics()["device"].startswith("cuda")
    for _ in range(70):
        trainer.step()
        population.step()
    pretraining = slice(0, config.pretraining_steps)
    columns = ("action", "action_source", "advised_action", "reward", "terminated", "truncated")
    for mine, theirs in zip(recorder.steps[pretraining], alone.steps[pretraining], strict=True):
        assert [getattr(mine, c) for c in columns] == [getattr(theirs, c) for c in columns]
        assert mine.q_grab == pytest.approx(theirs.q_grab, rel=Q_TOLERANCE, abs=1e-4)
    assert all(s.loss is not None for s in recorder.steps[60:])
