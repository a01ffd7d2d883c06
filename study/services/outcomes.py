"""Steps' outcomes for logs recorded before they were kept: each episode is replayed from
its reset seed and its logged actions (the environment is deterministic), and each step's
outcome (`sim.rewards.step_outcome`: placed, misplaced, lost, none) is filled in.

Rescoring uses the outcomes where every step of an episode has one
(`analysis.rescoring`); this gives old logs the same footing. Loads the simulator:
run it from the command line (`ideeprl outcomes --study ID`), not in the web process.
"""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy import select, update
from sqlalchemy.orm import Session

from sim.rewards import step_outcome
from study.db.models import Episode, Step, StudySession


@dataclass(frozen=True)
class Filled:
    """What a replay did for one session."""

    session_id: int
    steps: int
    """Steps whose outcome was filled in."""
    episodes: int
    """Episodes replayed."""
    without_seed: int
    """Episodes left as they were: recorded before reset seeds were kept."""


class ReplayMismatch(RuntimeError):
    """A replayed episode did not give its logged rewards: the environment or its options
    are not the ones the session ran with."""


def fill_outcomes(db: Session, session: StudySession) -> Filled:
    """Replay the session's episodes that have steps without an outcome; store them."""
    query = (
        select(Step.stage, Step.episode)
        .where(Step.session_id == session.id, Step.outcome.is_(None))
        .distinct()
    )
    wanted = {(stage, episode) for stage, episode in db.execute(query)}
    if not wanted:
        return Filled(session.id, 0, 0, 0)
    env = session.spec.make_env()
    filled = replayed = without_seed = 0
    try:
        episodes = db.scalars(
            select(Episode).where(Episode.session_id == session.id).order_by(Episode.id)
        )
        for episode in episodes:
            if (episode.stage, episode.episode) not in wanted:
                continue
            if episode.reset_seed is None:
                without_seed += 1
                continue
            steps = list(
                db.scalars(
                    select(Step)
                    .where(
                        Step.session_id == session.id,
                        Step.global_step.between(
                            episode.first_global_step, episode.last_global_step
                        ),
                    )
                    .order_by(Step.global_step)
                )
            )
            _, info = env.reset(seed=episode.reset_seed)
            for step in steps:
                _, reward, _, _, after = env.step(step.action)
                if abs(float(reward) - step.reward) > 1e-9:
                    raise ReplayMismatch(
                        f"session {session.id}, step {step.global_step}: the replay's reward "
                        "differs from the logged one"
                    )
                if step.outcome is None:
                    db.execute(
                        update(Step)
                        .where(Step.id == step.id)
                        .values(outcome=step_outcome(info, after))
                    )
                    filled += 1
                info = after
            replayed += 1
        db.commit()
    finally:
        env.close()
    return Filled(session.id, filled, replayed, without_seed)
