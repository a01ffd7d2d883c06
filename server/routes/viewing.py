"""What the participant's pages need beside the participant API: whether the 3-D view
is still playing the last move, and the learner's curve for the thank-you page."""

from fastapi import APIRouter, Request
from sqlalchemy import select

from server.deps import DbDep, ManagerDep, ParticipantDep
from server.live.trainers import QUEUED, shown_status
from study.db.models import Episode, StudySession
from study.schemas.participant import CurvePoint, LearningCurve, Playback

router = APIRouter(prefix="/api/participant", tags=["participant"])


@router.get("/playback")
def playback(session: ParticipantDep, request: Request) -> Playback:
    """Whether the participant's 3-D view still shows the robot moving: the page keeps
    the action buttons off until it has finished."""
    viewer = request.app.state.viewer
    return Playback(
        remaining_s=round(viewer.playback_remaining_s(session.id), 3),
        viewers=len(viewer.views(session.id)),
        scene_shown=viewer.scene_shown(session.id),
    )


@router.get("/learning-curve")
def learning_curve(session: ParticipantDep, db: DbDep, manager: ManagerDep) -> LearningCurve:
    """The learner's collected reward per training episode, as it trains on its own."""
    row = db.get(StudySession, session.id)
    assert row is not None, "a participant token reaches an existing session"
    episodes = db.execute(
        select(Episode.episode, Episode.collected_reward)
        .where(Episode.session_id == session.id, Episode.stage == "train")
        .order_by(Episode.episode)
    ).all()
    wait = manager.trainers.wait_s(session.id)
    status, place = shown_status(manager.trainers, session.id, manager.status(session.id))
    return LearningCurve(
        status=status,
        queued=status == QUEUED,
        queue_place=place,
        wait_s=round(wait, 1) if wait is not None else None,
        episodes=row.spec.config.episodes,
        curve=[CurvePoint(episode=e, collected_reward=r) for e, r in episodes],
    )
