"""How a step without a placement is scored: the reward schemes (SPEC 1, "Reward accounting").

The placements always earn the same (+1 the placement that completes the task, +0.4 any
other correct one, -1 a wrong one); the schemes differ only in what a step *without* a
placement costs. The authors' public code (IthanMoreira/DeppRL, commit 42ad270) scored
the two methods the paper compares differently, and the paper's R_T compares those two
accountings (shared/reference/README.md); a study that reproduces them names the scheme.
"""

from typing import Any, Literal

RewardScheme = Literal["paper", "authors-autonomous", "authors-interactive"]
REWARD_SCHEMES: tuple[RewardScheme, ...] = ("paper", "authors-autonomous", "authors-interactive")

STEP_PENALTY = -0.01
"""The cost unit of a step with no placement."""
MIN_STEPS = 18
"""6 objects x 3 actions: the shortest episode that sorts everything."""
AUTHORS_FREE_STEPS = 19
"""Steps of an episode that cost nothing in the authors' autonomous script.

Their `Deep_NN.py:228-231` rewrites a -0.01 step to 0 while the step counter `time` is at
most 18 and to -0.01 x (time - 18) after it; `time` starts at 0 and is incremented after
the step (`Deep_NN.py:254`), so at the n-th step of an episode `time` = n - 1: the first
19 steps are free and the n-th step costs -0.01 x (n - 19) from n = 20 on. Checked
against their logs: every autonomous episode of at most 18 steps carries no penalty."""


def step_penalty(scheme: str, episode_step: int) -> float:
    """What the `episode_step`-th step (from 1) of an episode costs when it places nothing.

    - `paper` (the paper's text, the default): 0 up to the 18th step, -0.01 after.
    - `authors-autonomous` (the authors' DeepRL script): 0 up to the 19th step, then a
      growing -0.01 x (n - 19) at the n-th step: an episode of 60 steps loses about 8.6.
    - `authors-interactive` (the authors' IDeepRL training loops,
      `Deep_NN_Interac_Agent-Entrenador.py:267-268`, where the rewrite is commented out):
      a flat -0.01 from the first step. Their pretraining and advising loops still used the
      growing rule, so their replay memory mixed both; this scheme applies one rule to the
      whole run.
    """
    if scheme == "paper":
        return STEP_PENALTY if episode_step > MIN_STEPS else 0.0
    if scheme == "authors-autonomous":
        over = episode_step - AUTHORS_FREE_STEPS
        return round(STEP_PENALTY * over, 10) if over > 0 else 0.0
    if scheme == "authors-interactive":
        return STEP_PENALTY
    raise ValueError(check_reward_scheme(scheme))


def check_reward_scheme(scheme: object) -> str:
    """The scheme itself when valid; else raises a `ValueError` naming the valid ones."""
    if scheme not in REWARD_SCHEMES:
        raise ValueError(
            f"reward_scheme must be one of {', '.join(REWARD_SCHEMES)} (paper: the paper's "
            f"text; authors-autonomous / authors-interactive: the authors' DeepRL / IDeepRL "
            f"scripts), got {scheme!r}"
        )
    return scheme


OUTCOMES = ("placed", "misplaced", "lost", "none")
"""What a step did to the objects: placed one where it belongs, placed one on the wrong
side, lost one (knocked off the center table), or none of these."""
COUNTS = {"placed": "placed_correct", "misplaced": "misplaced", "lost": "lost"}
"""Each outcome's counter in the environment's `info`."""


def step_outcome(before: dict[str, Any], after: dict[str, Any]) -> str:
    """The outcome of the step between two `info`s of one episode (`OUTCOMES`). A step does
    at most one of them: a grab may lose an object, a drop places one."""
    for outcome, count in COUNTS.items():
        if int(after.get(count, 0)) > int(before.get(count, 0)):
            return outcome
    return "none"


def is_placement(reward: float, terminated: bool, scheme: str, episode_step: int) -> bool:
    """Whether a logged step placed an object, from its reward under the scheme it was
    scored with: a placement's reward is never the scheme's step cost, except a wrong
    placement (-1), which always ends the episode (a step without a placement never does)."""
    return terminated or abs(reward - step_penalty(scheme, episode_step)) > 1e-9


def rescore(
    rewards: list[float],
    terminated: list[bool],
    scheme: str,
    to_scheme: str,
    outcomes: list[str | None] | None = None,
) -> list[float]:
    """One episode's logged rewards (scored under `scheme`) as `to_scheme` scores them:
    the placements keep their reward, every other step costs what `to_scheme` says.

    With the steps' `outcomes` (what each did: `OUTCOMES`) a placement is
    a step that placed an object, right or wrong; without them it is read from the reward
    (`is_placement`), which cannot tell an episode that ended because its last object was
    lost from one that ended by a placement, nor, under `authors-autonomous`, a 119th step's
    -1 cost from a wrong placement's -1."""
    check_reward_scheme(to_scheme)
    steps = enumerate(zip(rewards, terminated, strict=True), start=1)
    if outcomes is None:
        return [
            reward if is_placement(reward, ended, scheme, n) else step_penalty(to_scheme, n)
            for n, (reward, ended) in steps
        ]
    return [
        reward if outcome in ("placed", "misplaced") else step_penalty(to_scheme, n)
        for (n, (reward, _)), outcome in zip(steps, outcomes, strict=True)
    ]
