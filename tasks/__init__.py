"""Tasks: the environments a study's learners act in, each with what people need to advise
in it. A task is any Gymnasium environment with discrete actions whose observations are
uint8 RGB images (H, W, 3), H and W multiples of 8 (into the paper's network), or float
vectors (n,) (into a small dense network); the learner sees it only through the Gymnasium
API.

A task is named in a run (`RunSpec.task`) by one of:
- a built-in name: `sorting` (the paper's robot, the default), `gridworld` (MiniGrid) or
  `reach` (a robot arm reaching a ball, PyBullet);
- `package.module:callable`, a researcher's own: the module is imported (it must be
  importable by the server and its worker processes, e.g. installed, or on `PYTHONPATH`)
  and the callable, marked with `@task_factory`, returns a `Task`.

The ground truth an advisor may look at travels in the environment's `info`: a task whose
advisor can name the right action puts it in `info["correct_action"]` (the oracle advisor
reads it), or gives `correct_action` a function of `info` and the task's options; where
other actions are as right (two moves equally short), it lists them all in
`info["correct_actions"]`, the correct action among them, for the accuracy of advice and
ratings (`Task.correct_actions`). An
episode's success is Gymnasium's `info["is_success"]` at its end where the task states it
(else: it terminated without a misplacement, as the sorting robot's does).

Torch-free, PyBullet-free: a task's own module imports its simulator when an environment is
made.
"""

from __future__ import annotations

import importlib
import re
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym

BUILT_IN = {
    "sorting": "tasks.sorting:sorting_task",
    "gridworld": "tasks.gridworld:gridworld_task",
    "reach": "tasks.reach:reach_task",
}
"""The tasks this package brings, by name."""

_OWN = re.compile(r"^[A-Za-z_][\w]*(\.[A-Za-z_]\w*)*:[A-Za-z_]\w*$")
"""`package.module:callable`."""

OptionValue = str | int | float | bool | dict[str, str]
"""A task option's value: JSON's text, number or true/false (the sorting rule's map too)."""
TaskOptions = Mapping[str, OptionValue]
"""A run's options for its task, by name."""
EnvFactory = Callable[[TaskOptions, int, bool], gym.Env[Any, Any]]
"""(the run's task options, the episode's step limit, record the motion) -> environment."""


GymInfo = Mapping[str, Any]
"""An environment's `info`: Gymnasium's own untyped mapping, which a task fills as it likes."""


@dataclass(frozen=True)
class CheckQuestion:
    """A comprehension check's question about the task, with its right answer."""

    id: str
    """Lowercase letters, digits and _, starting with a letter (at most 40)."""
    text: str
    choices: tuple[str, ...]
    """2 to 8 distinct choices, each at most 500 characters, as the participant reads them."""
    answer: str
    """The right choice, one of `choices`."""

    def __post_init__(self) -> None:
        """A question a check page can ask: `TaskError` says what is wrong with it."""
        where = f"check question {self.id!r}"
        if not re.fullmatch(r"[a-z][a-z0-9_]{0,39}", self.id):
            raise TaskError(f"{where}: its id takes lowercase letters, digits and _")
        texts = (self.text, *self.choices)
        if not (2 <= len(self.choices) <= 8) or len(set(self.choices)) != len(self.choices):
            raise TaskError(f"{where}: it takes 2 to 8 different choices")
        if any(not isinstance(t, str) or not 1 <= len(t) <= 500 or "\x00" in t for t in texts):
            raise TaskError(f"{where}: its text and choices take 1 to 500 characters each")
        if self.answer not in self.choices:
            raise TaskError(f"{where}: its answer {self.answer!r} is not one of its choices")


@dataclass(frozen=True)
class Situations:
    """What a person sees that changes how hard the choice is, for advisors fitted to people
    (`learner.fitted`): each state's situation is a place within a group (the sorting robot:
    the arm's station within what it holds), and a situation's error rate is pulled toward
    its group's. A task without them is fitted by the run's stage within the correct action."""

    of: Callable[[GymInfo], tuple[str, str]]
    """(place, group) of the state `info` describes."""
    places: tuple[str, ...]
    groups: tuple[str, ...]


class TaskError(ValueError):
    """A task that cannot be found or made; the message says why, for a person."""


class RescoreError(ValueError):
    """Recorded steps a task cannot score under the scheme asked (what that scheme counts
    is not in the record, or the task declares no schemes); the message says why."""


@dataclass(frozen=True)
class RecordedEpisode:
    """One episode's recorded steps, as rescoring reads them (every step, in order)."""

    rewards: tuple[float, ...]
    """Each step's reward, as the run's scheme scored it."""
    terminated: tuple[bool, ...]
    """Whether the step ended the episode by the task's own end (Gymnasium's `terminated`,
    not the step limit's truncation)."""
    outcomes: tuple[str, ...] | None = None
    """Each step's outcome (`Task.outcomes`, or "none") where every step has one; None for
    steps recorded before outcomes were kept."""


Rescore = Callable[[RecordedEpisode, str, str, TaskOptions], list[float]]
"""(the episode, the scheme it was scored under, the scheme wanted, the run's task options)
-> each step's reward under the scheme wanted; `RescoreError` where the record cannot say."""


@dataclass(frozen=True)
class RewardSchemes:
    """A task's accountings of the same behaviour (what each step earns), and how a recorded
    episode scored under one is scored under another, so runs scored differently can be
    compared under one (`analysis.rescoring`)."""

    names: tuple[str, ...]
    """The schemes, the one runs are scored under by default first."""
    rescore: Rescore
    option: str = ""
    """The task option that names the scheme a run is scored under ("": every run is
    scored under the first)."""
    about: str = ""
    """How a recorded step is scored under another scheme, one sentence for the report."""

    def logged(self, options: TaskOptions) -> str:
        """The scheme a run with these task options was scored under."""
        if not self.option:
            return self.names[0]
        return str(options.get(self.option, self.names[0]))


@dataclass(frozen=True)
class TaskAction:
    """One action as a person meets it on the advice page."""

    word: str
    """The button's words, e.g. "move left"."""
    key: str = ""
    """The keyboard key that chooses it (one character, or an arrow's name), or none."""
    name: str = ""
    """Its name in records and exports (the export's `q_<name>` column): lowercase letters,
    digits and _; empty: made from its words (`Task.action_names`)."""

    def __post_init__(self) -> None:
        if self.name and not re.fullmatch(r"[a-z0-9_]{1,40}", self.name):
            raise TaskError(
                f"action {self.word!r}: its name {self.name!r} takes 1 to 40 lowercase "
                "letters, digits and _"
            )


@dataclass(frozen=True)
class ViewCamera:
    """Where a task's live 3-D view looks from when it opens (metres, world frame, z up)."""

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    fov: float = 50.0
    """Vertical, degrees."""


@dataclass(frozen=True)
class CorrectActions:
    """A step's correct action (the oracle's) and every action as right as it, which the
    accuracy of advice and ratings counts as right (the grid world's moves equally near
    the goal); none where the task cannot say."""

    action: int | None
    actions: tuple[int, ...]
    """Sorted; empty where `action` is None."""

    @property
    def stored(self) -> list[int] | None:
        """The right actions as stored beside an advice or a rating (None: none known)."""
        return list(self.actions) or None


NO_CORRECT_ACTION = CorrectActions(None, ())


def actions_text(actions: Sequence[int] | None) -> str | None:
    """Action indices as the export writes them, in one cell: "1 2" (None: none)."""
    return " ".join(str(int(a)) for a in actions) if actions else None


def actions_of_text(text: str | None) -> frozenset[int]:
    """The action indices of an `actions_text` cell (empty where it is empty)."""
    return frozenset(int(a) for a in text.split()) if text else frozenset()


@dataclass(frozen=True)
class Task:
    """A task: how to make its environment, and what people see of it."""

    name: str
    """How runs name it (`sorting`, `gridworld`, or `package.module:callable`)."""
    title: str
    """A few words for people: the page's heading."""
    make_env: EnvFactory
    """Makes the environment for the run's task options."""
    actions: tuple[TaskAction, ...]
    """The actions in the learner's order (action i is the network's output i)."""
    goal: str = ""
    """One sentence for the participant: what the agent must do."""
    options: TaskOptions = field(default_factory=dict)
    """The task options a run may set, with their defaults; others are refused."""
    correct_action: Callable[[GymInfo, TaskOptions], int | None] | None = None
    """The right action from (info, task options), for the oracle advisor; None: the
    environment's `info["correct_action"]` when it states one."""
    good_reward: float | None = None
    """An episode's reward a competent policy collects; an agent advisor's check asks for
    it (None: the check judges only that the advisor does not repeat one action)."""
    live_view: bool = False
    """The web page shows the task's live 3-D view; else frames. Its environment then has
    `scene_bodies()` and `body_poses()` (`sim.BodySpec`, `sim.Pose`; `sim.visuals` reads
    them from any PyBullet scene) and may have `last_motion`."""
    camera: ViewCamera | None = None
    """Where the live view looks from when it opens (None: the sorting robot's camera)."""
    check_questions: tuple[CheckQuestion, ...] = ()
    """The comprehension check's questions for a study of this task (an online study whose
    design keeps the default check asks these; none: one question on the task's goal)."""
    agent: str = "agent"
    """What the participant pages call the learner: "the agent", "the robot"."""
    texts: Mapping[str, str] = field(default_factory=dict)
    """The task's own participant page texts by key (title, consent, induction_1..3,
    thanks), over the pages' defaults for any task; a study's texts go over these."""
    preset: str = "paper"
    """The learner preset a run of this task starts from when it names none (the paper's
    DQN for the sorting robot; a vector task's learner is the dense network whatever its
    preset)."""
    outcomes: tuple[str, ...] = ()
    """What a step can do that the task counts beside its reward (the sorting robot's
    placements: placed, misplaced, lost), in its steps' `outcome`; none: its reward and
    success are its measures."""
    situations: Situations | None = None
    """The situations a fitted advisor conditions on (None: the stage and correct action)."""
    reward_schemes: RewardSchemes | None = None
    """Its reward schemes, for rescoring recorded runs (None: it declares none, and its
    runs are reported as logged, never rescored)."""

    @property
    def n_actions(self) -> int:
        return len(self.actions)

    @property
    def action_words(self) -> tuple[str, ...]:
        return tuple(a.word for a in self.actions)

    @property
    def action_names(self) -> tuple[str, ...]:
        """Each action's name in records and exports, in the learner's order (the export
        names the Q-value of action `move right` `q_move_right`): its declared `name`, else
        its words in lowercase with every run of other characters than a-z and 0-9 as one _.
        Where they would not tell every action apart (two alike, one empty, or `values`),
        the actions are named by their index: action_0, action_1, ..."""
        names = tuple(a.name or _name_of(a.word) for a in self.actions)
        if len(set(names)) == len(names) and all(n and n != "values" for n in names):
            return names
        return tuple(f"action_{i}" for i in range(len(names)))

    def checked_options(self, given: TaskOptions | None) -> dict[str, OptionValue]:
        """The run's task options with the task's defaults filled in; `TaskError` names an
        option the task does not have."""
        given = dict(given or {})
        unknown = sorted(set(given) - set(self.options))
        if unknown:
            allowed = ", ".join(sorted(self.options)) or "none"
            raise TaskError(
                f"task {self.name} has no option {unknown[0]!r} (its options: {allowed})"
            )
        for name, value in given.items():
            if not _same_kind(value, self.options[name]):
                kind = type(self.options[name]).__name__
                raise TaskError(f"task {self.name}'s option {name!r} must be of type {kind}")
        return {**self.options, **given}

    def env(
        self, options: TaskOptions | None, max_episode_steps: int, record_motion: bool
    ) -> gym.Env[Any, Any]:
        return self.make_env(self.checked_options(options), max_episode_steps, record_motion)

    def rescore(
        self, episode: RecordedEpisode, scheme: str, to_scheme: str, options: TaskOptions
    ) -> list[float]:
        """Each step of a recorded episode (scored under `scheme`) as `to_scheme` scores it;
        `RescoreError` says why where the task cannot (no schemes, an unknown scheme, or
        what `to_scheme` counts is not in the record)."""
        schemes = self.reward_schemes
        if schemes is None:
            raise RescoreError(
                f"task {self.name} declares no reward schemes: its runs' rewards are reported "
                "as logged, not rescored"
            )
        for name in (scheme, to_scheme):
            if name not in schemes.names:
                raise RescoreError(
                    f"task {self.name} has no reward scheme {name!r} (its schemes: "
                    f"{', '.join(schemes.names)})"
                )
        if len(episode.terminated) != len(episode.rewards) or (
            episode.outcomes is not None and len(episode.outcomes) != len(episode.rewards)
        ):
            raise RescoreError("an episode's rewards, ends and outcomes differ in length")
        return schemes.rescore(episode, scheme, to_scheme, {**self.options, **options})

    def correct(self, info: GymInfo, options: TaskOptions) -> int | None:
        """The right action in the state `info` describes, or None where nobody can say."""
        if self.correct_action is not None:
            return self.correct_action(info, self.checked_options(options))
        action = info.get("correct_action")
        return None if action is None else int(action)

    def correct_actions(self, info: GymInfo, options: TaskOptions) -> CorrectActions:
        """The correct action in the state `info` describes (`correct`, what the oracle
        advises) and every action as right as it: the environment's
        `info["correct_actions"]` where it lists them, else the correct action alone."""
        action = self.correct(info, options)
        if action is None:
            return NO_CORRECT_ACTION
        listed = info.get("correct_actions")
        actions = {action} if listed is None else {int(a) for a in listed} | {action}
        return CorrectActions(action, tuple(sorted(actions)))


def _name_of(words: str) -> str:
    """An action's name made from its words: "Move right!" -> move_right."""
    return re.sub(r"[^a-z0-9]+", "_", words.lower()).strip("_")


def _same_kind(value: Any, default: Any) -> bool:
    """Whether an option's value has its default's JSON type (an int stands for a float)."""
    if isinstance(default, bool) or isinstance(value, bool):
        return isinstance(value, bool) and isinstance(default, bool)
    if isinstance(default, int):
        return isinstance(value, int)
    if isinstance(default, float):
        return isinstance(value, int | float)
    return default is None or isinstance(value, type(default))


_FACTORY = "__ideeprl_task_factory__"
_made: dict[str, Task] = {}


def task_factory(function: Callable[[], Task]) -> Callable[[], Task]:
    """Marks a function of a researcher's module as one that returns a `Task`: only marked
    functions may be named as `module:callable` (a run names code the server will call)."""
    setattr(function, _FACTORY, True)
    return function


def task_names() -> tuple[str, ...]:
    return tuple(BUILT_IN)


def get_task(name: str) -> Task:
    """The task a run names; `TaskError` says why when it cannot be had."""
    if name in _made:
        return _made[name]
    reference = BUILT_IN.get(name, name)
    if not isinstance(reference, str) or not _OWN.match(reference):
        raise TaskError(
            f"unknown task {name!r}: a built-in one ({', '.join(BUILT_IN)}) or "
            "package.module:callable, a function marked @tasks.task_factory"
        )
    module_name, attribute = reference.split(":")
    if module_name.split(".")[0] in sys.stdlib_module_names:
        raise TaskError(f"task {name}: {module_name} is a module of Python's, not a task's")
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        raise TaskError(
            f"task {name}: module {module_name!r} cannot be imported ({error.msg}); it must be "
            "importable by the server and its workers (installed, or on PYTHONPATH)"
        ) from None
    factory = getattr(module, attribute, None)
    if not callable(factory) or not getattr(factory, _FACTORY, False):
        raise TaskError(f"task {name}: {reference} is not a function marked @tasks.task_factory")
    task = factory()
    if not isinstance(task, Task):
        raise TaskError(f"task {name}: {reference}() returned {type(task).__name__}, not a Task")
    if task.name != name:
        task = Task(**{**task.__dict__, "name": name})
    _made[name] = task
    return task


__all__ = [
    "BUILT_IN",
    "CheckQuestion",
    "OptionValue",
    "RecordedEpisode",
    "RescoreError",
    "RewardSchemes",
    "Situations",
    "Task",
    "TaskAction",
    "TaskError",
    "TaskOptions",
    "ViewCamera",
    "get_task",
    "task_factory",
]
