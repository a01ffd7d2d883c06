"""Playing a recorded episode back in the dashboard: its page, the JSON it reads, and the
relay of its 3-D view.

Opening a playback reruns the episode in a process of its own (`server.live.playbacks`);
the page then steps through the steps on its own (play, pause, step), shows each step's
logged action, source and reward with the image the learner saw, and tells the server
which step it shows so the 3-D view (`server.viewer.episodes`) draws it. Behind the
dashboard's login, as the rest of the dashboard.
"""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, HTTPException, Path, Request, WebSocket
from fastapi.responses import RedirectResponse, Response
from sqlalchemy import select

from runs.worker.rerun import RerunOrder
from server.deps import DbDep
from server.live.playbacks import Playback, Playbacks, TooManyPlaybacks
from server.routes.dashboard import LoginDep, _logged_in
from server.routes.pages import scene_src, templates
from server.routes.params import MAX_ID, AdviceIndex, SessionId
from server.viewer.connection import TOKEN_PATH
from server.viewer.episodes import PlaybackViewer
from server.viewer.proxy import relay_to, upstream_host
from study.db.models import Advice, Episode
from study.schemas.playback import (
    AdviceShown,
    EpisodeRow,
    PlaybackOpened,
    PlaybackState,
    Show,
    StepShown,
)
from study.services import sessions
from study.services.playback import RecordedEpisode, recorded_episode

router = APIRouter(include_in_schema=False)
API = "/dashboard/api"
Stage = Annotated[Literal["pretrain", "train"], Path(description="pretrain or train.")]
EpisodeNumber = Annotated[int, Path(ge=1, le=MAX_ID, description="From 1 within its stage.")]
PlaybackId = Annotated[str, Path(pattern=r"^[A-Za-z0-9_-]{1,64}$")]
StepIndex = Annotated[int, Path(ge=0, le=MAX_ID, description="0-based step of the episode.")]


def _playbacks(request: Request) -> Playbacks:
    return request.app.state.playbacks


def _viewer(request: Request) -> PlaybackViewer:
    return request.app.state.playback_viewer


def _open(request: Request, playback_id: str) -> Playback:
    playback = _playbacks(request).get(playback_id)
    if playback is None:
        raise HTTPException(404, "no such playback: it was closed, or idle too long; open it again")
    return playback


# --- the page ----------------------------------------------------------------------------
@router.get("/dashboard/sessions/{session_id}/playback")
def playback_page(request: Request, db: DbDep, session_id: SessionId) -> Response:
    if not _logged_in(request):
        return RedirectResponse("/dashboard/login", status_code=303)
    session = sessions.get_session(db, session_id)
    return templates.TemplateResponse(
        request,
        "dashboard/playback.html",
        {
            "site_title": "IDeepRL dashboard",
            "session": session,
            "scene_src": scene_src(request, session.spec.the_task),
            "action_names": session.spec.the_task.action_words,
        },
    )


# --- episodes, and opening one -----------------------------------------------------------
@router.get(f"{API}/sessions/{{session_id}}/episodes", dependencies=[LoginDep])
def episodes(db: DbDep, session_id: SessionId) -> list[EpisodeRow]:
    """The session's episodes, pretraining first, as the page's list offers them."""
    sessions.get_session(db, session_id)
    found = db.scalars(
        select(Episode).where(Episode.session_id == session_id).order_by(Episode.first_global_step)
    )
    return [
        EpisodeRow(
            stage=e.stage,
            episode=e.episode,
            steps=e.steps,
            collected_reward=e.collected_reward,
            advised_steps=e.advised_steps,
            playable=e.reset_seed is not None,
        )
        for e in found
    ]


def rerun_order(recorded: RecordedEpisode) -> RerunOrder:
    """What the rerun's process needs of the recorded episode."""
    assert recorded.episode.reset_seed is not None, "checked by recorded_episode"
    return RerunOrder(
        spec=recorded.session.spec,
        reset_seed=recorded.episode.reset_seed,
        actions=[s.action for s in recorded.steps],
        rewards=[s.reward for s in recorded.steps],
    )


@router.post(
    f"{API}/sessions/{{session_id}}/episodes/{{stage}}/{{episode}}/playback",
    dependencies=[LoginDep],
    status_code=201,
)
def open_playback(
    request: Request, db: DbDep, session_id: SessionId, stage: Stage, episode: EpisodeNumber
) -> PlaybackOpened:
    """Rerun the episode in a worker process; 429 when `playback_limit` are open."""
    recorded = recorded_episode(db, session_id, stage, episode)
    _viewer(request).ensure_started()
    order = rerun_order(recorded)
    try:
        playback = _playbacks(request).start(session_id, stage, episode, order, recorded)
    except TooManyPlaybacks as error:
        raise HTTPException(429, str(error), headers={"Retry-After": "30"}) from None
    return PlaybackOpened(id=playback.id, url=f"{API}/playbacks/{playback.id}")


# --- an open playback ----------------------------------------------------------------------
def _state(playback: Playback) -> PlaybackState:
    recorded: RecordedEpisode = playback.recorded
    base = f"{API}/playbacks/{playback.id}"
    first = recorded.episode.first_global_step
    names = recorded.session.spec.the_task.action_words  # its task's words
    ready = playback.state == "ready"
    return PlaybackState(
        id=playback.id,
        session_id=playback.session_id,
        method=recorded.session.method,
        stage=playback.stage,
        episode=playback.episode,
        state=playback.state,
        detail=playback.detail,
        collected_reward=recorded.episode.collected_reward,
        steps=[
            StepShown(
                index=i,
                step=s.episode_step,
                global_step=s.global_step,
                action=s.action,
                action_name=names[s.action],
                action_source=s.action_source,
                reward=s.reward,
                image_url=f"{base}/steps/{i}.png",
            )
            for i, s in enumerate(recorded.steps)
        ]
        if ready
        else [],
        end_image_url=f"{base}/steps/{len(recorded.steps)}.png" if ready else "",
        advice=[
            AdviceShown(
                advice_index=a.advice_index,
                global_step=a.global_step,
                index=a.global_step - first,
                action=a.action,
                action_name=names[a.action],
                advisor=a.advisor,
                decision_time_s=a.decision_time_s,
                response_time_s=a.response_time_s,
                image_url=f"{API}/sessions/{playback.session_id}/advice/{a.advice_index}.png",
            )
            for a in recorded.advice
        ],
    )


@router.get(f"{API}/playbacks/{{playback_id}}", dependencies=[LoginDep])
def get_playback(request: Request, playback_id: PlaybackId) -> PlaybackState:
    """The playback's state, and its steps once the rerun is ready; each request keeps it
    open for another `playback_idle_s`."""
    return _state(_open(request, playback_id))


@router.get(f"{API}/playbacks/{{playback_id}}/steps/{{index}}.png", dependencies=[LoginDep])
def step_image(request: Request, playback_id: PlaybackId, index: StepIndex) -> Response:
    playback = _open(request, playback_id)
    rerun = playback.rerun
    if rerun is None:
        raise HTTPException(409, f"the episode is still {playback.state}: {playback.detail}")
    if index > len(rerun.steps):
        raise HTTPException(
            404, f"the episode has {len(rerun.steps)} steps: 0 to {len(rerun.steps)} (its end)"
        )
    png = rerun.final_png if index == len(rerun.steps) else rerun.steps[index].observation_png
    return Response(png, media_type="image/png")


@router.post(f"{API}/playbacks/{{playback_id}}/show", dependencies=[LoginDep])
def show(request: Request, playback_id: PlaybackId, body: Show) -> dict[str, int]:
    """The 3-D view draws the step the page shows; returns how many views drew it."""
    playback = _open(request, playback_id)
    rerun = playback.rerun
    if rerun is None:
        raise HTTPException(409, f"the episode is still {playback.state}; wait for it to be ready")
    if body.index > len(rerun.steps):
        raise HTTPException(
            422,
            f"index: the episode has {len(rerun.steps)} steps, 0 to {len(rerun.steps)} (its end)",
        )
    return {"views": _viewer(request).show(playback_id, body.index)}


@router.delete(f"{API}/playbacks/{{playback_id}}", dependencies=[LoginDep], status_code=204)
def close_playback(request: Request, playback_id: PlaybackId) -> Response:
    """The page is leaving: the rerun (if still running) and the 3-D views end."""
    if not _playbacks(request).close(playback_id):
        raise HTTPException(404, "no such playback (closed already, or idle too long)")
    return Response(status_code=204)


@router.get(f"{API}/sessions/{{session_id}}/advice/{{advice_index}}.png", dependencies=[LoginDep])
def advice_image(db: DbDep, session_id: SessionId, advice_index: AdviceIndex) -> Response:
    """The image an advisor was shown, as stored with the advice."""
    sessions.get_session(db, session_id)
    png = db.scalar(
        select(Advice.observation_png).where(
            Advice.session_id == session_id, Advice.advice_index == advice_index
        )
    )
    if png is None:
        raise HTTPException(404, f"session {session_id} has no advice {advice_index}")
    return Response(png, media_type="image/png")


# --- the 3-D view's websocket ----------------------------------------------------------------
@router.websocket("/viewer/playback/{playback_id}")
@router.websocket("/viewer/playback/{playback_id}/")
async def relay(websocket: WebSocket, playback_id: str) -> None:
    """The playback page's 3-D view, relayed to the playbacks' viser server (which admits
    only open playbacks' ids)."""
    viewer: PlaybackViewer = websocket.app.state.playback_viewer
    port = viewer.port
    if not TOKEN_PATH.match(f"/p/{playback_id}") or port is None:
        await websocket.close(code=1008)
        return
    await relay_to(websocket, f"ws://{upstream_host(viewer.host)}:{port}/p/{playback_id}")
