"""Sessions of a study: create, read, start/pause/resume/stop, progress, learning curve.
The services return the session rows; `session_public` makes them the API's response
(the dashboard's too)."""

from typing import Literal

from fastapi import APIRouter, BackgroundTasks, Query, Request
from fastapi.responses import Response
from sqlalchemy import select

from learner.run import declared
from server.deps import DbDep, ManagerDep, ResearcherDep, SettingsDep
from server.live.manager import SessionManager
from server.live.trainers import QUEUED, shown_status
from server.routes.paging import PageDep
from server.routes.params import AdviceIndex, SessionId, StudyId
from study.db.models import LIVE_STATUSES, Advice, Status, StudySession
from study.schemas.runs import given
from study.schemas.sessions import (
    AdvicePublic,
    EpisodePublic,
    Progress,
    SessionCreated,
    SessionOptions,
    SessionPublic,
    session_create_model,
)
from study.services import assignment, sessions, storage
from study.services.errors import NotFound
from study.settings import Settings

router = APIRouter(prefix="/api", tags=["sessions"], dependencies=[ResearcherDep])


def session_public(
    session: StudySession, base_url: str, manager: SessionManager | None = None
) -> SessionPublic:
    """A session as the API shows it; its participant's link under `base_url`; `queued`
    with its place while it waits for a trainer slot (`shown_status`, from `manager`)."""
    data = {
        name: getattr(session, name)
        for name in SessionPublic.model_fields
        if name not in ("participant", "participant_url", "texts_version")
        and hasattr(session, name)
    }
    if session.texts_version is not None:
        data["texts_version"] = session.texts_version.version
    if session.participant is not None:
        data["participant"] = session.participant.pseudonym
    if session.participant_token:
        data["participant_url"] = sessions.participant_url(base_url, session.participant_token)
    trainers = manager.trainers if manager is not None else None
    data["status"], data["queue_place"] = shown_status(trainers, session.id, session.status)
    return SessionPublic(**data)


def creation_router() -> APIRouter:
    """The route that creates a session, its body made from the run's declaration in force
    (`learner.run.declared`: a field declared there is in the body and its OpenAPI
    schema)."""
    creating = APIRouter(prefix="/api", tags=["sessions"], dependencies=[ResearcherDep])
    body_model = session_create_model()

    @creating.post("/studies/{study_id}/sessions", status_code=201)
    def create_session(
        db: DbDep,
        settings: SettingsDep,
        manager: ManagerDep,
        background: BackgroundTasks,
        study_id: StudyId,
        body: body_model,  # type: ignore[valid-type]
        pretrain: bool | None = Query(
            default=None,
            description="A human session: start its random pretraining now, so the robot "
            "is ready for the first turn when the participant's induction ends; false: it "
            "starts when the participant opens the link. Unset: the server's "
            "pretrain_on_create (on; each practised session holds a worker process).",
        ),
    ) -> SessionCreated:
        """A session: `run` (the run, learner.run.RunSpec, every field optional: unset ones
        take their defaults, the config's its preset's) and the session's own options.
        Every value is checked before anything is stored: a bad one is a 422 naming the
        field and what it allows. The run is stored validated and with its numerics pinned
        on this machine (device, precision, threads)."""
        values = given(body)
        run = values.pop("run")
        if run.get("version", 0) is None:  # the document allows null: the current version
            del run["version"]
        spec = declared().from_json(run)
        if spec.method == "human" and "seed" not in run:
            spec = assignment.numbered_seed(db, study_id, spec)
        options = SessionOptions(**values)
        session = sessions.create_session(
            db,
            study_id,
            spec,
            options,
            settings.data_dir,
            settings.worker_threads,
            shared_root=settings.shared_root,
        )
        # see delete_session
        storage.remove_session_files(settings.checkpoint_root, session.id, None)
        public = session_public(session, settings.base_url)
        practise = settings.pretrain_on_create if pretrain is None else pretrain
        if practise and session.participant_token:
            practise_ahead(background, manager, settings, session.id)
        return SessionCreated(**public.model_dump(), participant_token=session.participant_token)

    return creating


def practise_ahead(
    background: BackgroundTasks, manager: SessionManager, settings: Settings, session_id: int
) -> None:
    """Start a human session's practice after the response, ahead of its participant, if
    fewer than `pretrain_ahead_limit` sessions wait for theirs; else its link starts it."""
    if manager.practise_ahead(session_id, settings.pretrain_ahead_limit):
        background.add_task(manager.welcome_ahead, session_id)


@router.get("/studies/{study_id}/sessions")
def list_sessions(
    db: DbDep, settings: SettingsDep, manager: ManagerDep, study_id: StudyId, page: PageDep
) -> list[SessionPublic]:
    found = page.of(sessions.list_sessions(db, study_id))
    return [session_public(s, settings.base_url, manager) for s in found]


@router.get("/sessions/{session_id}")
def get_session(
    db: DbDep, settings: SettingsDep, manager: ManagerDep, session_id: SessionId
) -> SessionPublic:
    return session_public(sessions.get_session(db, session_id), settings.base_url, manager)


@router.delete("/sessions/{session_id}", status_code=204)
def delete_session(
    request: Request, db: DbDep, settings: SettingsDep, manager: ManagerDep, session_id: SessionId
) -> Response:
    """A session with its records, advice images and checkpoints, and the study's report
    (built from them); refused while it runs. How a participant's data is deleted."""
    current = manager.live(session_id)
    live = current is not None and current.status in LIVE_STATUSES
    storage.delete_session(db, settings.data_dir, session_id, live, settings.checkpoint_root)
    request.app.state.participant_tokens.clear()
    request.app.state.playbacks.close_deleted(db)
    return Response(status_code=204)


def on_cluster(manager: SessionManager, session_id: int, status: Status, detail: str = "") -> bool:
    """The researcher's control of a session that trains on the Ray cluster, written to its
    row for its task to read (`server.live.cluster`); False for any other session."""
    return manager.cluster is not None and manager.cluster.control(session_id, status, detail)


def _fresh(
    db: DbDep, settings: SettingsDep, session_id: int, manager: SessionManager
) -> SessionPublic:
    db.expire_all()
    return session_public(sessions.get_session(db, session_id), settings.base_url, manager)


@router.post("/sessions/{session_id}/start")
async def start_session(
    db: DbDep, settings: SettingsDep, manager: ManagerDep, session_id: SessionId
) -> SessionPublic:
    await manager.start(session_id)
    return _fresh(db, settings, session_id, manager)


@router.post("/sessions/{session_id}/pause")
async def pause_session(
    db: DbDep, settings: SettingsDep, manager: ManagerDep, session_id: SessionId
) -> SessionPublic:
    if not on_cluster(manager, session_id, Status.paused, ""):
        await manager.pause(session_id)
    return _fresh(db, settings, session_id, manager)


@router.post("/sessions/{session_id}/resume")
async def resume_session(
    db: DbDep,
    settings: SettingsDep,
    manager: ManagerDep,
    session_id: SessionId,
    override_numerics: bool = Query(
        default=False,
        description="Resume on this machine's numerics although the run was pinned to others "
        "it cannot honour (recorded in numerics_overrides); without it such a resume is a 409 "
        "saying why.",
    ),
) -> SessionPublic:
    if not on_cluster(manager, session_id, Status.running):
        await manager.resume(session_id, override_numerics)
    return _fresh(db, settings, session_id, manager)


@router.post("/sessions/{session_id}/stop")
async def stop_session(
    db: DbDep, settings: SettingsDep, manager: ManagerDep, session_id: SessionId
) -> SessionPublic:
    if not on_cluster(manager, session_id, Status.stopped, "stopped by the researcher"):
        await manager.stop(session_id)
    return _fresh(db, settings, session_id, manager)


@router.get("/sessions/{session_id}/progress")
def get_progress(db: DbDep, manager: ManagerDep, session_id: SessionId) -> Progress:
    session = sessions.get_session(db, session_id)
    current = manager.live(session_id)
    live = current.progress if current is not None and current.progress is not None else None
    data = vars(live) if live is not None else dict(session.progress)
    status, place = shown_status(
        manager.trainers, session_id, current.status if current is not None else session.status
    )
    advice_given = int(data.get("advice_given", 0))
    spec = session.spec
    return Progress(
        session_id=session_id,
        status=status,
        stage=data.get("stage"),
        global_step=int(data.get("global_step", 0)),
        episode=int(data.get("episode", 0)),
        episodes=spec.config.episodes,
        epsilon=data.get("epsilon"),
        collected_reward=float(data.get("collected_reward", 0.0)),
        last_episode_reward=data.get("last_episode_reward"),
        advice_given=advice_given,
        advice_budget=spec.advice_budget,
        advice_left=max(0, spec.advice_budget - advice_given),
        advice_wanted=current is not None and current.request is not None,
        queued=status == QUEUED,
        queue_place=place,
        consented=session.consented_at is not None,
    )


@router.get("/sessions/{session_id}/episodes")
def list_episodes(
    db: DbDep,
    session_id: SessionId,
    page: PageDep,
    stage: Literal["train", "pretrain", "all"] = Query(
        default="train", description="train: the learning curve; pretrain; or all."
    ),
) -> list[EpisodePublic]:
    """The learning curve: collected reward (and more) per episode, in order."""
    found = sessions.list_episodes(db, session_id)
    chosen = [e for e in found if stage in ("all", e.stage)]
    return [EpisodePublic.model_validate(e) for e in page.of(chosen)]


@router.get("/sessions/{session_id}/advice")
def list_advice(db: DbDep, session_id: SessionId, page: PageDep) -> list[AdvicePublic]:
    sessions.get_session(db, session_id)
    query = select(Advice).where(Advice.session_id == session_id).order_by(Advice.advice_index)
    query = query.offset(page.offset).limit(page.limit)
    return [AdvicePublic.model_validate(a) for a in db.scalars(query)]


@router.get(
    "/sessions/{session_id}/advice/{advice_index}.png",
    response_class=Response,
    responses={200: {"content": {"image/png": {}}}},
)
def advice_observation(db: DbDep, session_id: SessionId, advice_index: AdviceIndex) -> Response:
    sessions.get_session(db, session_id)
    png = db.scalar(
        select(Advice.observation_png).where(
            Advice.session_id == session_id, Advice.advice_index == advice_index
        )
    )
    if png is None:
        raise NotFound(f"session {session_id} has no advice {advice_index}")
    return Response(png, media_type="image/png")
