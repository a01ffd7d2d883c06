"""What travels over the duplex pipe between the web process and a session's worker.

Plain frozen dataclasses, pickled by multiprocessing. Worker -> web: `Progress`,
`AdviceRequest`, `AdviceResult`, `EpisodeDone`, `SceneReset`, `SceneStep`, `StatusChanged`,
`TrainingWanted`. Web -> worker: `AdviceAnswer`, `RatingAnswer`, `Command` (`ready`: the participant
consented and finished the induction; `train`: a trainer slot is free; `handover`: a
trainer slot is free for a population, see `runs.worker.population`). A population's
worker sends its sessions' messages `Tagged` with their session over its one channel.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

from tasks import NO_CORRECT_ACTION, CorrectActions

if TYPE_CHECKING:  # the web process reads these without loading the simulator
    from learner.records import EpisodeRecord
    from sim.bodies import BodySpec, MotionFrame, Pose


@dataclass(frozen=True)
class Progress:
    stage: str
    """`pretraining` or `training`."""
    global_step: int
    """Environment steps taken so far (pretraining included)."""
    episode: int
    """Training episodes finished."""
    episodes: int
    """Training episodes the session will run."""
    epsilon: float
    """Current exploration rate."""
    collected_reward: float
    """Reward collected in the current episode so far."""
    last_episode_reward: float | None
    """Collected reward of the last finished training episode."""
    advice_given: int
    """Advice received so far."""
    advice_budget: int
    """Advice the strategy may ask for in all."""
    queued: bool = False
    """Waiting in the server's queue for a free trainer slot (human sessions after advice)."""
    waiting_for_participant: bool = False
    """Ready for advice, waiting for the participant's consent and induction."""


@dataclass(frozen=True)
class AdviceRequest:
    advice_index: int
    """0-based index of this advice in the session."""
    global_step: int
    """The step the advice is for."""
    greedy_action: int
    """The learner's own greedy choice at this step (the web process writes the advice row,
    complete, from this request and the answer: `study.services.advice`)."""
    observation_png: bytes
    """The 64x64 image the learner sees, PNG (lossless)."""
    info: dict[str, Any]
    """The environment's ground truth at this step; participants are shown only what the arm
    holds and where, in words (the scene shows it too)."""
    advice_budget: int
    """Advice the strategy may ask for in all."""
    frame_png: bytes | None = None
    """A task without a live 3-D view: what people see at this step, PNG."""
    correct: CorrectActions = NO_CORRECT_ACTION
    """The task's correct action at this step and every action as right (stored with the
    advice or the rating for its accuracy; never shown to the participant); none where the
    task cannot say."""
    rated_action: int | None = None
    """Evaluative feedback: the action the learner took at this step, for the person to rate
    (good, bad, or no answer); None: advice is asked for (`runs.worker.rating`)."""
    rated_reward: float | None = None
    """Evaluative feedback: the reward the rated action earned (the step is taken)."""
    rating_time_out_s: float = 0.0
    """Evaluative feedback: how long the learner waits for the rating (the run's
    `rating_time_out_s`); after it the web process records no answer."""


@dataclass(frozen=True)
class AdviceResult:
    advice_index: int
    """Which advice was carried out."""
    action: int
    """The action taken."""
    reward: float
    """Reward of the advised step."""
    episode_over: bool
    """The step ended its episode."""


@dataclass(frozen=True)
class EpisodeDone:
    record: EpisodeRecord
    """The episode's record, as the learner wrote it."""


@dataclass(frozen=True)
class SceneReset:
    bodies: list[BodySpec]
    """`sim.BodySpec` of every body in the scene (static for the scene)."""
    poses: dict[str, Pose]
    """`sim.Pose` of every body, by name."""
    episode: int
    """Training episode the reset starts (pretraining resets carry -1)."""


@dataclass(frozen=True)
class SceneStep:
    action: int
    """The action just taken."""
    reward: float
    """Its reward."""
    frames: list[MotionFrame]
    """`sim.MotionFrame`s along the motion (empty in fast mode without recording)."""
    poses: dict[str, Pose]
    """`sim.Pose` of every body after the step."""
    global_step: int
    """The step's global step (from 1, as the learner's StepRecord)."""
    advised: bool = False
    """The step carried out the participant's advice: the only steps the 3-D view replays
    as motion (the others it shows at their end, so it never makes a person wait)."""


@dataclass(frozen=True)
class StatusChanged:
    status: str
    """New status (see `study.db.models.Status`)."""
    detail: str = ""
    """Why, for failures and abandonment."""


@dataclass(frozen=True)
class TrainingWanted:
    """A human session's advice is over: it asks for one of the server's trainer slots
    and waits (queued) until `Command("train")` grants it."""


@dataclass(frozen=True)
class Tagged:
    """A message of one of a population's sessions, on the population's one channel."""

    session_id: int
    message: Any


@dataclass(frozen=True)
class AdviceAnswer:
    advice_index: int
    action: int


@dataclass(frozen=True)
class RatingAnswer:
    advice_index: int
    judgement: float | None
    """+1 good, -1 bad; None: no answer within the time-out."""


@dataclass(frozen=True)
class Command:
    name: Literal[
        "pause",
        "resume",
        "stop",
        "watch",
        "unwatch",
        "shutdown",
        "ready",
        "train",
        "assigned",
        "handover",
    ]
    reason: str = ""
    """Why (`stop`), for the session's status detail."""
    session_id: int | None = None
    """The session a `stop` is for, in a population's shared channel (None: every one)."""


WorkerMessage = (
    Progress
    | AdviceRequest
    | AdviceResult
    | EpisodeDone
    | SceneReset
    | SceneStep
    | StatusChanged
    | TrainingWanted
)
