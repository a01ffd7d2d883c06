"""Is a trained advisor fit to advise? `../shared/SPEC.md` section 5's rule, checked before it
advises and stored beside its checkpoint.

The replication's `authors` advisor was stuck: from the states where it advised (after the
random pretraining) it repeated one action, or alternated two, for long stretches (89 grabs
in a row) and placed 4 to 31 objects in 100 advised steps where a working policy places
about 33. Its advised runs then measured the advising procedure, not advice. So an advisor
is evaluated two ways, both with its greedy policy, in the run's own scenario:

- on `EPISODES` fresh episodes: its mean collected reward must reach `MIN_REWARD` and no
  action may repeat more than `MAX_REPEAT` times in a row;
- from the states where it will advise: the run is built exactly as it will run (its seed,
  its random pretraining) and stepped to the end of pretraining, where early advising asks
  the advisor; its advice is counted (placements right and wrong, objects lost, the longest
  repeat) and must not repeat more than `MAX_REPEAT` times in a row either.

The result (`AdvisorCheck`) is written as JSON beside the checkpoint (`PATH.check.json`),
keyed by the checkpoint's content hash and the run it was checked for, so a batch checks a
checkpoint once.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from learner.run import RunSpec

CHECK_VERSION = 1
EPISODES = 10
MIN_REWARD = 2.5
"""The mean collected reward an advisor's greedy policy must reach (3.0 at best)."""
MAX_REPEAT = 10
"""The most times in a row it may take one action (crossing the scene takes 2 moves)."""
EVALUATION_SEED = 7_000_000
"""Fresh episodes are reset with seeds from here: apart from every run's own draws."""


class AdvisorCheckFailed(ValueError):
    """An advisor failed its check and was not allowed to advise."""


@dataclass(frozen=True)
class AdviceQuality:
    """What an advisor's advice did where it advised: counted from the steps it chose."""

    advice: int
    """Advised steps counted."""
    placed: int
    """Objects placed on their correct table by an advised action."""
    misplaced: int
    """Objects placed on the wrong table."""
    lost: int
    """Objects knocked off the center table."""
    longest_repeat: int
    """The most advised steps in a row with one action."""

    @classmethod
    def of(cls, actions: Sequence[int], outcomes: Sequence[str]) -> AdviceQuality:
        return cls(
            advice=len(actions),
            placed=sum(o == "placed" for o in outcomes),
            misplaced=sum(o == "misplaced" for o in outcomes),
            lost=sum(o == "lost" for o in outcomes),
            longest_repeat=longest_repeat(actions),
        )


@dataclass(frozen=True)
class AdvisorCheck:
    """One advisor checkpoint checked for one kind of run."""

    checkpoint_sha256: str
    run_key: str
    """What the check depends on besides the network: scene, reward scheme, episode length,
    pretraining and advice budget, the seeds advised from (`run_key`)."""
    rewards: tuple[float, ...]
    """Collected reward of each fresh greedy episode."""
    episode_longest_repeat: int
    """The most times in a row the greedy policy took one action in a fresh episode."""
    at_advice: tuple[AdviceQuality, ...]
    """Its advice from the advice-time states, one per seed advised from (empty when the
    strategy advises during training, where those states depend on the learner)."""
    advice_seeds: tuple[int, ...]
    min_reward: float | None = MIN_REWARD
    """The mean reward the greedy policy must collect (the task's good reward; None: the
    task names none, and only repeats are judged)."""
    max_repeat: int = MAX_REPEAT
    version: int = CHECK_VERSION
    problems: tuple[str, ...] = field(default=())
    placements: bool = True
    """Whether the task counts the robot's placements (`Task.outcomes`), which the summary
    then gives for the advice; else the task's own measures only."""
    success_rate: float | None = None
    """The share of the fresh episodes that succeeded (None: the task states no success)."""

    @property
    def mean_reward(self) -> float:
        return sum(self.rewards) / len(self.rewards) if self.rewards else math.nan

    @property
    def passed(self) -> bool:
        return not self.problems

    def summary(self) -> str:
        advice = ", ".join(
            f"seed {seed}: "
            + (f"{q.placed} placed, {q.misplaced} misplaced, {q.lost} lost, "
               if self.placements else "")
            + f"longest repeat {q.longest_repeat} in {q.advice} advice"
            for seed, q in zip(self.advice_seeds, self.at_advice, strict=True)
        )  # fmt: skip
        verdict = "passed" if self.passed else "FAILED: " + "; ".join(self.problems)
        needs = f" (needs {self.min_reward})" if self.min_reward is not None else ""
        success = "" if self.success_rate is None else f", success rate {self.success_rate:.2f}"
        return (
            f"advisor check {verdict}. Greedy on {len(self.rewards)} fresh episodes: mean "
            f"reward {self.mean_reward:.2f}{needs}{success}, longest repeat "
            f"{self.episode_longest_repeat} (at most {self.max_repeat})"
            + (f". From the advice-time states: {advice}" if advice else "")
        )

    def to_json(self) -> dict[str, Any]:
        data = asdict(self)
        data["mean_reward"] = self.mean_reward
        data["passed"] = self.passed
        return data

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> AdvisorCheck:
        data = {k: v for k, v in data.items() if k not in ("mean_reward", "passed")}
        data["rewards"] = tuple(data["rewards"])
        data["at_advice"] = tuple(AdviceQuality(**q) for q in data["at_advice"])
        data["advice_seeds"] = tuple(data["advice_seeds"])
        data["problems"] = tuple(data["problems"])
        return cls(**data)


def longest_repeat(actions: Sequence[int]) -> int:
    """The longest run of one action in `actions`."""
    best = run = 0
    previous = None
    for action in actions:
        run = run + 1 if action == previous else 1
        previous = action
        best = max(best, run)
    return best


def checkpoint_hash(path: str | Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def run_key(spec: RunSpec, advice_seeds: Sequence[int], episodes: int) -> str:
    """What a check depends on besides the network, as a short stable text."""
    spec = spec.validate()
    parts = {
        "sort_rule": spec.sort_rule,
        "scenario": spec.scenario.to_dict(),
        "motion": spec.motion,
        "max_episode_steps": spec.config.max_episode_steps,
        "pretraining_steps": spec.config.pretraining_steps,
        "advice_budget": spec.config.advice_budget,
        "strategy": spec.strategy,
        "preset": spec.preset,
        "advice_seeds": list(advice_seeds),
        "episodes": episodes,
        "version": CHECK_VERSION,
    }
    if spec.task != "sorting":  # (the sorting robot's keys as they were before tasks)
        parts.update(task=spec.task, task_options=spec.task_options)
    return hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()[:16]


def check_path(checkpoint: str | Path) -> Path:
    return Path(str(checkpoint) + ".check.json")


def stored_check(
    checkpoint: str | Path, spec: RunSpec, advice_seeds: Sequence[int], episodes: int = EPISODES
) -> AdvisorCheck | None:
    """The check stored beside `checkpoint` for this run, if the checkpoint is unchanged."""
    path = check_path(checkpoint)
    if not path.is_file():
        return None
    try:
        stored = json.loads(path.read_text())
        checks = [AdvisorCheck.from_json(c) for c in stored.get("checks", [])]
    except (ValueError, TypeError, KeyError):
        return None
    digest, key = checkpoint_hash(checkpoint), run_key(spec, advice_seeds, episodes)
    return next((c for c in checks if c.checkpoint_sha256 == digest and c.run_key == key), None)


def last_check(checkpoint: str | Path) -> AdvisorCheck | None:
    """The check last stored beside `checkpoint` (for whichever run), None if there is none
    (or it cannot be read): whether the advisor there passed or failed when last checked."""
    try:
        checks = json.loads(check_path(checkpoint).read_text()).get("checks", [])
        return AdvisorCheck.from_json(checks[-1]) if checks else None
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        return None


def save_check(checkpoint: str | Path, check: AdvisorCheck) -> Path:
    """Add `check` to the checks stored beside `checkpoint` (one per run key)."""
    path = check_path(checkpoint)
    checks: list[dict[str, Any]] = []
    if path.is_file():
        try:
            checks = json.loads(path.read_text()).get("checks", [])
        except ValueError:
            checks = []
    checks = [
        c
        for c in checks
        if not (
            c.get("run_key") == check.run_key
            and c.get("checkpoint_sha256") == check.checkpoint_sha256
        )
    ]
    checks.append(check.to_json())
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps({"checks": checks}, indent=2, sort_keys=True))
    tmp.replace(path)
    return path


def check_advisor(
    checkpoint: str | Path,
    spec: RunSpec,
    advice_seeds: Sequence[int] = (),
    episodes: int = EPISODES,
) -> AdvisorCheck:
    """Evaluate the checkpoint's greedy policy for runs like `spec` (an advised run; its
    method and checkpoint are replaced): `episodes` fresh episodes, then its advice from the
    advice-time states of each of `advice_seeds` (default: the run's own seed)."""
    from learner.advisors import AgentAdvisor

    spec = spec.replace(method="agent", advisor_checkpoint=str(checkpoint)).validate()
    seeds = tuple(advice_seeds) or (spec.seed,)
    advisor = AgentAdvisor(checkpoint)
    rewards: list[float] = []
    succeeded: list[bool] = []
    repeat = 0
    env = spec.make_env()
    try:
        for episode in range(episodes):
            obs, info = env.reset(seed=EVALUATION_SEED + episode)
            total, actions, done = 0.0, [], False
            while not done:
                action = advisor.advise(obs, info)
                actions.append(action)
                obs, reward, terminated, truncated, info = env.step(action)
                total += float(reward)
                done = terminated or truncated
            rewards.append(total)
            if "is_success" in info:
                succeeded.append(bool(info["is_success"]))
            repeat = max(repeat, longest_repeat(actions))
    finally:
        env.close()
    found = [(s, _advice_from_pretraining(spec.replace(seed=s))) for s in seeds]
    by_seed = [(seed, quality) for seed, quality in found if quality is not None]
    at_advice = tuple(quality for _, quality in by_seed)
    problems = []
    mean = sum(rewards) / len(rewards)
    good = spec.the_task.good_reward
    if good is not None and mean < good:
        problems.append(f"its greedy policy collects {mean:.2f} on average, under {good}")
    if repeat > MAX_REPEAT:
        problems.append(f"it repeats one action {repeat} times in a row in fresh episodes")
    for seed, quality in by_seed:
        if quality.longest_repeat > MAX_REPEAT:
            problems.append(
                f"from the advice-time states of seed {seed} it repeats one action "
                f"{quality.longest_repeat} times in a row"
            )
    return AdvisorCheck(
        checkpoint_sha256=checkpoint_hash(checkpoint),
        run_key=run_key(spec, seeds, episodes),
        rewards=tuple(rewards),
        episode_longest_repeat=repeat,
        at_advice=at_advice,
        advice_seeds=seeds if at_advice else (),
        problems=tuple(problems),
        min_reward=good,
        placements=bool(spec.the_task.outcomes),
        success_rate=sum(succeeded) / len(succeeded) if succeeded else None,
    )


def _advice_from_pretraining(spec: RunSpec) -> AdviceQuality | None:
    """Early advising's advice as the run will get it: the run built as it will run, stepped
    through its pretraining (random steps, then the advisor's); None for other strategies,
    whose advice-time states depend on what the learner has learned."""
    if spec.strategy != "early" or spec.advice_budget == 0:
        return None
    trainer, env = spec.build()
    actions: list[int] = []
    outcomes: list[str] = []
    try:
        while trainer.global_step < spec.config.pretraining_steps:
            record = trainer.step()
            if record.action_source == "advisor":
                actions.append(record.action)
                outcomes.append(record.outcome)
    finally:
        env.close()
    return AdviceQuality.of(actions, outcomes)


def checked_advisor(
    checkpoint: str | Path,
    spec: RunSpec,
    advice_seeds: Sequence[int] = (),
    episodes: int = EPISODES,
    allow_failed: bool = False,
) -> AdvisorCheck:
    """The stored check, or a new one (stored); raises `AdvisorCheckFailed` when the advisor
    fails and `allow_failed` is false."""
    seeds = tuple(advice_seeds) or (spec.seed,)
    check = stored_check(checkpoint, spec, seeds, episodes)
    if check is None:
        check = check_advisor(checkpoint, spec, seeds, episodes)
        save_check(checkpoint, check)
    if not check.passed and not allow_failed:
        raise AdvisorCheckFailed(
            f"the advisor {checkpoint} failed its check ({'; '.join(check.problems)}); train "
            "another, or allow it explicitly (--allow-failed-advisor)"
        )
    return check
