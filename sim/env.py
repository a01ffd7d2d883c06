"""The Gymnasium environment: thin glue between the arm, the scene, the task and the camera."""

import copy
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded

from sim.actions import ACTION_NAMES, Action
from sim.bodies import BodySpec, MotionFrame, Pose
from sim.camera import IMAGE_SIZE, Camera
from sim.layout import CameraPose, Layout
from sim.rewards import RewardScheme
from sim.robot import SuctionArm
from sim.rules import OBJECTS, SortRule, SortRuleSpec
from sim.scenario import ScenarioOptions
from sim.scene import Scene
from sim.task import SortingTask, StepEvents
from sim.world import World

MOTIONS = ("physics", "fast")
FAST_MOVE_SECONDS = 0.5
"""Playback time a viewer gets for a fast-mode move (which takes no simulated time)."""


class SortingEnv(gym.Env[np.ndarray, np.int64]):
    """The paper's sorting task: a 64x64 RGB image in, one of four actions out.

    `motion="physics"` moves the arm through simulated steps (people watch it);
    `motion="fast"` sets the same poses directly (batch training). Both obey the same
    rules and render through the same camera. An episode is truncated after
    `max_episode_steps` steps (made by `gym.make`, Gymnasium's TimeLimit does that).

    `reward_scheme` says what a step without a placement costs (`sim.rewards`). The
    realism rates make the authors' imperfect scene (shared/reference/README.md, "The
    scene"): `grasp_failure_rate` is the chance that a grab comes back empty (the arm goes
    down and up above the center table, nothing is held), `knock_off_rate` the chance that
    a grab knocks one other remaining object off the center table (it is *lost*: out of
    the task, without reward or penalty). Both are seeded draws from `np_random`, in both
    motion modes (the physics mode can also fail a grasp or push an object off by itself,
    rarely); at 0 (the default) nothing is drawn, so runs are as without the options.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 4}  # noqa: RUF012 (as gymnasium.Env declares it)

    def __init__(
        self,
        motion: str = "physics",
        sort_rule: SortRuleSpec | SortRule = "color",
        max_episode_steps: int = 250,
        record_motion: bool = False,
        render_mode: str | None = None,
        reward_scheme: RewardScheme = "paper",
        grasp_failure_rate: float = 0.0,
        knock_off_rate: float = 0.0,
    ) -> None:
        # Every constructor argument, for a copy or an unpickled env (see `__deepcopy__`).
        self._init_kwargs = {k: v for k, v in locals().items() if k not in ("self", "__class__")}
        if motion not in MOTIONS:
            raise ValueError(
                f"motion must be 'physics' (the arm moves through simulated steps, for people "
                f"to watch) or 'fast' (the same poses set directly, for batch runs), got {motion!r}"
            )
        if (
            isinstance(max_episode_steps, bool)
            or not isinstance(max_episode_steps, int | np.integer)
            or max_episode_steps < 1
        ):
            raise ValueError(f"max_episode_steps must be a positive int, got {max_episode_steps!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        options = ScenarioOptions(reward_scheme, grasp_failure_rate, knock_off_rate)
        self.reward_scheme = options.reward_scheme
        self.grasp_failure_rate = options.grasp_failure_rate
        self.knock_off_rate = options.knock_off_rate
        self.motion = motion
        self.sort_rule = SortRule.parse(sort_rule)
        self.max_episode_steps = int(max_episode_steps)
        self.record_motion = record_motion
        self.render_mode = render_mode
        self.observation_space = spaces.Box(0, 255, (IMAGE_SIZE, IMAGE_SIZE, 3), np.uint8)
        self.action_space = spaces.Discrete(len(Action))

        self.layout = Layout()
        self._world = World()
        self._build()
        self._camera = Camera(self._world, self.layout.camera)
        self._task = SortingTask(
            self.sort_rule,
            {obj.name: (obj.shape, obj.color) for obj in self._scene.objects},
            self.reward_scheme,
        )
        self._slots_used = {"left": 0, "right": 0}
        self._needs_reset = True
        self._obs = np.zeros(self.observation_space.shape, np.uint8)
        self.last_motion: list[MotionFrame] = []
        """With `record_motion=True`: the moving bodies along the last step (or reset)."""
        self._episode_start: Mapping[str, Any] | None = None
        self._episode_actions: list[int] = []

    # -- Gymnasium API ------------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self._episode_start = copy.deepcopy(self.np_random.bit_generator.state)
        self._episode_actions = []
        if self.motion == "physics":
            # Contact caches, sleeping timers and solver warm starts survive PyBullet's
            # saveState/restoreState; only a rebuilt world continues exactly as a new one.
            self._build()
        else:
            self._arm.reset()
        self._scene.place_objects(self.np_random)
        self._task.reset()
        self._slots_used = {"left": 0, "right": 0}
        self._needs_reset = False
        if self.record_motion:
            self._world.start_recording()
            self.last_motion = self._world.stop_recording()
        self._obs = self._camera.image()
        return self._obs.copy(), self._info()

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        action = _parse_action(action)
        if self._needs_reset:
            raise ResetNeeded(
                "the episode has ended (or never started): call env.reset() before env.step()"
            )
        self._episode_actions.append(int(action))
        if self.record_motion:
            self._world.start_recording()
        events, moved = self._act(action)
        lost = tuple(
            name
            for name in self._task.remaining
            if name != events.grabbed
            and not self._scene.is_on(self._objects[name], self.layout.center_table)
        )
        events = StepEvents(events.grabbed, events.placed, lost)
        reward, terminated = self._task.update(events)
        limit = self._step_limit()
        truncated = not terminated and limit is not None and self._task.episode_step >= limit
        self._needs_reset = terminated or truncated
        if self.record_motion:
            pause = FAST_MOVE_SECONDS if moved and self.motion == "fast" else 0.0
            self.last_motion = self._world.stop_recording(pause)
        self._obs = self._camera.image()
        return self._obs.copy(), reward, terminated, truncated, self._info()

    def _step_limit(self) -> int | None:
        """The constructor's `max_episode_steps`, unless `gym.make` made this env (it sets
        `spec`): then Gymnasium's TimeLimit truncates, after the registered 250 steps or
        gym.make's own `max_episode_steps` (never passed on to the env), and the env must
        not cut an episode shorter."""
        return None if self.spec is not None else self.max_episode_steps

    def _build(self) -> None:
        """The whole scene, from an empty simulation."""
        self._world.reset()
        self._scene = Scene(self._world, self.layout)
        self._objects = {obj.name: obj for obj in self._scene.objects}
        self._arm = SuctionArm(
            self._world,
            self.layout,
            physics=self.motion == "physics",
            half_heights={obj.body: obj.half_height for obj in self._scene.objects},
        )

    def render(self) -> np.ndarray | None:
        """The agent's last observation, for `render_mode="rgb_array"`."""
        return self._obs.copy() if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        self._world.close()

    # -- scene mirroring ----------------------------------------------------------------

    def scene_bodies(self) -> list[BodySpec]:
        """Every body's name, shape and colour (the same for the env's whole life)."""
        return list(self._world.specs)

    def body_poses(self) -> dict[str, Pose]:
        """Every body's current world pose, by name."""
        return self._world.poses()

    def visible_pixels(
        self, camera: CameraPose | None = None, size: tuple[int, int] = (IMAGE_SIZE, IMAGE_SIZE)
    ) -> dict[str, int]:
        """How many of the camera's pixels each named body covers now (for checking the
        camera setup; renders once more). `camera` and `size` (width, height) check another
        view of the scene, such as the participants' 3-D view."""
        by_part = {(part.body, part.link): name for name, part in self._world.parts.items()}
        eye = self._camera if camera is None else Camera(self._world, camera, *size)
        counts = eye.visible_pixels()
        return {name: counts.get(key, 0) for key, name in by_part.items()}

    # -- the actions --------------------------------------------------------------------

    def _act(self, action: Action) -> tuple[StepEvents, bool]:
        """Carry out one action (SPEC 1); returns what happened and whether the arm moved."""
        arm = self._arm
        held = None if arm.held is None else self._scene.by_body[arm.held].name
        if action == Action.GRAB:
            if held is not None:
                if arm.station == "center":
                    return StepEvents(), False
                arm.go_to("center")
                return StepEvents(), True
            if not self._task.remaining:
                return StepEvents(), False
            remaining = self._task.remaining
            target = remaining[int(self.np_random.integers(len(remaining)))]
            if self._chance(self.grasp_failure_rate):
                arm.go_to("center")
                grabbed = None
            else:
                picked = arm.grab(
                    self._objects[target].body, [self._objects[name].body for name in remaining]
                )
                grabbed = None if picked is None else self._scene.by_body[picked].name
            others = [name for name in remaining if name != grabbed]
            if others and self._chance(self.knock_off_rate):
                victim = others[int(self.np_random.integers(len(others)))]
                self._scene.knock_off(self._objects[victim])
            return StepEvents(grabbed=grabbed), True
        if action in (Action.MOVE_RIGHT, Action.MOVE_LEFT):
            station = "right" if action == Action.MOVE_RIGHT else "left"
            if arm.station == station:
                return StepEvents(), False
            arm.go_to(station)
            return StepEvents(), True
        if held is None or arm.station == "center":
            return StepEvents(), False
        side = arm.station
        arm.drop(side, self._slots_used[side])
        self._slots_used[side] += 1
        return StepEvents(placed=(held, side)), True  # type: ignore[arg-type]

    def _chance(self, rate: float) -> bool:
        """A seeded draw with probability `rate`; none at all at 0, so default runs keep
        their random streams."""
        return rate > 0.0 and bool(self.np_random.random() < rate)

    def _info(self) -> dict[str, Any]:
        """The task's ground truth with values of one type and shape at every step and in
        every env, so Gymnasium's vector envs can stack them (docs/architecture.md)."""
        truth = self._task.info()
        held = truth.pop("held")
        left = {f"{kind['shape']}/{kind['color']}" for kind in truth.pop("remaining")}
        on_center = tuple(name in left for name in OBJECTS)
        return {
            "station": self._arm.station,
            "held": "" if held is None else f"{held['shape']}/{held['color']}",
            "held_shape": "" if held is None else held["shape"],
            "held_color": "" if held is None else held["color"],
            "remaining": len(left),
            "on_center": on_center,
            **truth,
        }

    # -- copies -------------------------------------------------------------------------

    def __deepcopy__(self, memo: dict[int, Any]) -> "SortingEnv":
        """A copy with its own PyBullet connection, in the same state: sharing the client
        would let the copy's garbage collection disconnect the original."""
        clone = _rebuild(*self._copy_state())
        memo[id(self)] = clone
        return clone

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled as its constructor arguments, RNG and the episode's actions so far;
        unpickling builds a new world and replays them (determinism makes it exact)."""
        return (_rebuild, self._copy_state())

    def _copy_state(self) -> tuple[Any, ...]:
        rng = self._np_random
        return (
            type(self),
            dict(self._init_kwargs),
            self.spec,
            self._np_random_seed,
            None if rng is None else copy.deepcopy(rng.bit_generator.state),
            copy.deepcopy(self._episode_start),
            list(self._episode_actions),
        )


def _generator(state: dict[str, Any]) -> np.random.Generator:
    bit_generator = getattr(np.random, state["bit_generator"])()
    bit_generator.state = state
    return np.random.Generator(bit_generator)


def _rebuild(
    cls: type[SortingEnv],
    kwargs: dict[str, Any],
    spec: Any,
    seed: int | None,
    rng_state: dict[str, Any] | None,
    episode_start: dict[str, Any] | None,
    actions: list[int],
) -> SortingEnv:
    """A new env in the state of the one `_copy_state` described: the same episode's reset
    replayed from the RNG state it started with, then its actions."""
    env = cls(**kwargs)
    env.spec = spec
    if episode_start is not None:
        env._np_random = _generator(episode_start)
        env.reset()
        for action in actions:
            env.step(action)
    if rng_state is not None:
        env._np_random = _generator(rng_state)
    env._np_random_seed = seed
    return env


def _parse_action(action: Any) -> Action:
    """The action as an `Action`, or a `ValueError` that says what is allowed."""
    value = action
    if isinstance(value, np.ndarray) and value.shape == ():
        value = value.item()
    valid = ", ".join(f"{i} ({name})" for i, name in enumerate(ACTION_NAMES))
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
        raise ValueError(f"action must be an integer, one of {valid}; got {action!r}")
    if not 0 <= int(value) < len(Action):
        raise ValueError(f"action must be one of {valid}; got {action!r}")
    return Action(int(value))
