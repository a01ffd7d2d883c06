"""Tasks: the built-in grid world, a researcher's own task named as module:callable, and
the run's rules about which fields belong to which task."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import tasks
from learner.advisors import AgentAdvisor
from learner.run import RunSpec, RunSpecError
from tasks import TaskError, get_task

CATCH = Path(__file__).resolve().parents[2] / "docs" / "examples" / "catch"


@pytest.fixture
def catch_importable(monkeypatch):
    """The example task's folder on the path, as PYTHONPATH puts it for the server."""
    monkeypatch.syspath_prepend(str(CATCH))
    yield "catch:catch_task"
    tasks._made.pop("catch:catch_task", None)
    sys.modules.pop("catch", None)


def small(**run) -> RunSpec:
    config = {"episodes": 3, "pretraining_steps": 64, "advice_budget": 30, "batch_size": 16,
              "memory_size": 300, "max_episode_steps": 40, "torch_threads": 1}  # fmt: skip
    return RunSpec.from_json({**run, "config": {**config, **run.get("config", {})}})


def test_the_grid_world_is_a_gymnasium_env_whose_correct_moves_reach_the_goal() -> None:
    env = get_task("gridworld").env({}, 250, False)
    check_env(env, skip_render_check=True)
    for seed in range(5):
        obs, info = env.reset(seed=seed)
        assert obs.shape == (64, 64, 3) and obs.dtype == np.uint8
        steps, distance = 0, info["distance"]
        while True:
            obs, reward, terminated, truncated, info = env.step(info["correct_action"])
            steps += 1
            if terminated or truncated:
                break
        assert terminated and not truncated and steps == distance and reward > 0.5


def test_the_grid_worlds_correct_actions_are_every_move_nearer_the_goal() -> None:
    """Where two moves are equally short (above and left of the goal: right and down), both
    are right; the correct action, the oracle's, is the first of them in action order."""
    task = get_task("gridworld")
    env = task.env({}, 250, False)
    both = 0
    for seed in range(8):
        _, info = env.reset(seed=seed)
        distance = info["distance"]
        right = task.correct_actions(info, {})
        assert right.action == info["correct_action"] == right.actions[0]
        assert list(right.actions) == info["correct_actions"] and right.stored == list(
            right.actions
        )
        for action in range(4):
            env.reset(seed=seed)
            _, _, _, _, after = env.step(action)
            nearer = after["distance"] == distance - 1
            assert nearer == (action in right.actions), (seed, action)
        both += right.actions == (1, 2)
    assert both, "some start is above and left of the goal, where right and down both are right"
    assert task.correct_actions({"correct_action": None}, {}).stored is None


def test_the_grid_world_is_the_same_for_the_same_seed_and_moves_as_people_see_them() -> None:
    env = get_task("gridworld").env({"size": 6}, 250, False)
    first, info = env.reset(seed=7)
    again, _ = env.reset(seed=7)
    assert np.array_equal(first, again) and first.shape == (48, 48, 3)
    x, y = info["position"]
    env.step(2)  # down: one row lower on screen
    assert env.unwrapped._position() in ((x, y + 1), (x, y))  # a wall stops it


def test_task_options_are_checked_by_name_and_type() -> None:
    task = get_task("gridworld")
    assert task.checked_options({"size": 6}) == {"size": 6, "max_steps": 64}
    with pytest.raises(TaskError, match="no option 'colour'"):
        task.checked_options({"colour": "red"})
    with pytest.raises(TaskError, match="type int"):
        task.checked_options({"size": "six"})


@pytest.mark.parametrize(
    ("name", "why"),
    [
        ("nope", "unknown task"),
        ("os:system", "module of Python's"),
        ("json:dumps", "module of Python's"),
        ("tests.tasks.test_tasks:small", "not a function marked"),
        ("no_such_module_here:make", "cannot be imported"),
    ],
)
def test_a_task_that_cannot_be_had_is_refused_with_why(name: str, why: str) -> None:
    with pytest.raises(TaskError, match=why):
        get_task(name)
    with pytest.raises(RunSpecError, match=why):
        RunSpec.from_json({"task": name}).validate()


@pytest.mark.parametrize(
    ("run", "field"),
    [
        ({"task": "gridworld", "sort_rule": "shape"}, "sort_rule"),
        ({"task": "gridworld", "scenario": {"knock_off_rate": 0.1}}, "scenario"),
        ({"task": "gridworld", "task_options": {"sizes": 3}}, "task_options"),
        ({"task": "sorting", "task_options": {"size": 3}}, "task_options"),
    ],
)
def test_each_tasks_fields_belong_to_it(run: dict, field: str) -> None:
    with pytest.raises(RunSpecError) as error:
        RunSpec.from_json(run).validate()
    assert error.value.field == field


def test_an_oracle_advised_grid_world_run_learns_from_the_correct_moves() -> None:
    spec = small(task="gridworld", method="oracle")
    trainer, _ = spec.build()
    records = []
    while not trainer.done:
        records.append(trainer.step())
    advised = [r for r in records if r.advised_action is not None]
    assert len(advised) == 30 and trainer.n_actions == 4
    assert all(r.q_values is None and r.q_drop is not None for r in records)


def test_a_researchers_own_task_runs_with_its_own_number_of_actions(
    catch_importable, tmp_path
) -> None:
    spec = small(task=catch_importable, method="oracle", task_options={"paddle_width": 4})
    trainer, env = spec.build()
    records = []
    while not trainer.done:
        records.append(trainer.step())
    assert trainer.n_actions == 3 and env.observation_space.shape == (32, 32, 3)
    assert {r.action for r in records} <= {0, 1, 2}
    assert all(r.q_grab is None and len(json.loads(r.q_values)) == 3 for r in records)
    # its checkpoint advises with three actions on its own image size
    trainer.save_checkpoint(tmp_path / "catch.pt", spec.to_json(), memory=False)
    advisor = AgentAdvisor(tmp_path / "catch.pt")
    obs, _ = env.reset(seed=1)
    assert advisor.q_values(obs).shape == (3,)


def test_the_sb3_baseline_takes_the_tasks_actions() -> None:
    """Stable-Baselines3's DQN on a task of five actions defined in the tests (its CNN
    needs 36 pixels a side or more: 40 here)."""
    pytest.importorskip("stable_baselines3")
    spec = small(task="tests.tasks.line:line_task", method="sb3-dqn", config={"advice_budget": 0})
    trainer, _ = spec.build()
    records = []
    while not trainer.done:
        records.append(trainer.step())
    assert trainer.model.q_net.action_space.n == 5
    assert {r.action for r in records} == {0, 1, 2, 3, 4}


def test_an_episodes_success_is_the_tasks_own_where_it_states_one(catch_importable) -> None:
    """The catch task ends every episode (caught or missed): success is its `is_success`,
    not the termination; the grid world's is reaching the goal."""
    for task, options in ((catch_importable, {"paddle_width": 1}), ("gridworld", {})):
        spec = small(task=task, method="random", task_options=options)
        trainer, _ = spec.build()
        episodes = []
        while not trainer.done:
            trainer.step()
            if trainer.episode_record is not None:
                episodes.append(trainer.episode_record)
        assert episodes
        for episode in episodes:
            if task == "gridworld":
                assert episode.success == episode.terminated
            elif episode.terminated:
                assert episode.success == (episode.collected_reward > 0)


@pytest.mark.parametrize(
    ("question", "why"),
    [
        (("goal-1", "Where?", ("a", "b"), "a"), "its id takes lowercase letters"),
        (("goal", "Where?", ("a",), "a"), "2 to 8 different choices"),
        (("goal", "Where?", ("a", "a"), "a"), "2 to 8 different choices"),
        (("goal", "Where?", ("a", "b"), "c"), "is not one of its choices"),
        (("goal", "x" * 501, ("a", "b"), "a"), "1 to 500 characters"),
    ],
)
def test_a_tasks_check_question_a_page_cannot_ask_is_refused(question, why) -> None:
    """Refused when the task is declared, not when a participant's page asks it."""
    with pytest.raises(TaskError, match=why):
        tasks.CheckQuestion(*question)


def test_the_trust_checklist_names_the_tasks_agent() -> None:
    """A grid world participant rates the agent they advised, never a robot; the sorting
    robot's checklist keeps its words, and the items their ids."""
    from study.schemas.visit import QuestionnaireSpec

    spec = QuestionnaireSpec.default()
    robot = {s.instrument: s for s in spec.sections()}["trust"]
    agent = {s.instrument: s for s in spec.sections(get_task("gridworld").agent)}["trust"]
    assert [i.id for i in agent.items] == [i.id for i in robot.items]
    assert robot.title == "The robot" and "robot" in robot.items[0].text
    shown = " ".join([agent.title, agent.intro, *(i.text for i in agent.items)])
    assert "robot" not in shown and agent.title == "The agent"
