"""The participant's pages: entry link, consent, the paper's three-step induction, the
advice page with the live 3-D view, and the thank-you page.

Where a participant is comes from the session itself, so a reload or a new tab returns
to the same point: until they consent (recorded on the server, whoever started the
session) the link shows the consent page; then the induction (the page in the URL) until
they press Start; then they advise until the budget is spent; then they are thanked.
Opening the link starts the session's random pretraining, so the robot is ready when the
induction ends. Page texts come from the study's `texts` (keys in `TEXT_KEYS`), else from
the session's task (`tasks.Task.texts`: the sorting robot's are in `tasks/sorting/texts/`),
else from `web/texts/`, the texts for any task; once a participant consented, their pages
show the stored version they consented to.
"""

from __future__ import annotations

import html
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fastapi import APIRouter, Form, Request
from fastapi.responses import HTMLResponse, RedirectResponse, Response
from fastapi.staticfiles import StaticFiles
from fastapi.templating import Jinja2Templates
from markupsafe import Markup
from sqlalchemy import func, select
from starlette.concurrency import run_in_threadpool

import sim
from server.live.visits import end_visit
from server.viewer.camera import VIEWER_CAMERA, viser_camera_params
from study.db.models import Advice, Outcome, PanelId, Status
from study.schemas.design import StudyDesign
from study.schemas.instruments import PREFER_NOT_TO_SAY
from study.schemas.participant import CheckChoice, CheckQuestionShown, CheckState
from study.schemas.visit import Section
from study.services import consent as consent_service
from study.services import visit as visit_service
from study.services.errors import Conflict, Invalid
from study.services.feedback import judgements_given
from study.services.sessions import session_for_token
from study.services.visit import CheckProgress
from tasks import Task, get_task

WEB_DIR = Path(__file__).resolve().parents[2] / "web"
templates = Jinja2Templates(directory=WEB_DIR / "templates")
router = APIRouter(include_in_schema=False)

TEXT_KEYS = ("title", "consent", "induction_1", "induction_2", "induction_3", "thanks")
"""Keys of a study's `texts` that replace the default page texts: its task's own
(`Task.texts`), else those for any task (web/texts/KEY.txt)."""
KEY_NAMES = {"ArrowUp": "↑", "ArrowRight": "→", "ArrowDown": "↓", "ArrowLeft": "←", " ": "space"}
"""How the pages write a key that is not one character."""


def induction_titles(task: Task) -> tuple[str, str, str]:
    return (f"The {task.agent} and the experiment", "The task, and how to solve it", "Your screen")


def key_name(key: str) -> str:
    return KEY_NAMES.get(key, key.upper() if len(key) == 1 else key)


templates.env.globals["key_name"] = key_name


def task_words(task: Task) -> dict[str, str]:
    """The placeholders a page text may hold about its task and what learns in it."""
    article = "an" if task.agent[:1].lower() in "aeiou" else "a"
    keyed = [a for a in task.actions if a.key]
    return {
        "{agent}": task.agent,
        "{agent_the}": f"the {task.agent}",
        "{Agent_the}": f"The {task.agent}",
        "{agent_a}": f"{article} {task.agent}",
        "{Agent_a}": f"{article.capitalize()} {task.agent}",
        "{task_title}": task.title,
        "{task_goal}": task.goal or task.title,
        "{task_actions}": "\n".join(f"- **{a.word.capitalize()}**" for a in task.actions),
        "{task_keys}": ", ".join(f"**{key_name(a.key)}** {a.word}" for a in keyed)
        or "no keys: use the buttons",
    }


def default_text(key: str, task: Task, feedback: str = "advice") -> str:
    """A page text before a study's: the task's own, else the one for any task; under
    evaluative feedback, its version for ratings (KEY.evaluative) where there is one."""
    if feedback != "advice":
        kind = task.texts.get(f"{key}.{feedback}")
        if kind is None and task.texts.get(key) is None:
            path = WEB_DIR / "texts" / f"{key}.{feedback}.txt"
            kind = path.read_text() if path.exists() else None
        if kind is not None:
            return kind
    return task.texts.get(key) or (WEB_DIR / "texts" / f"{key}.txt").read_text()


def static_files() -> StaticFiles:
    return StaticFiles(directory=WEB_DIR / "static")


def check_state(progress: CheckProgress) -> CheckState:
    """The comprehension check as the participant sees it (this page and
    `GET /api/participant/check`): its questions and choices, never their answers, and
    their tries."""
    spec = progress.spec
    if spec is None:
        return CheckState(required=False)
    return CheckState(
        required=True,
        questions=[
            CheckQuestionShown(
                id=q.id,
                text=q.text,
                choices=[CheckChoice(value=c.value, label=c.label) for c in q.choices],
            )
            for q in spec.questions
        ],
        tries=spec.tries,
        tries_used=progress.tries_used,
        passed=progress.passed,
        excluded=progress.excluded,
    )


@dataclass(frozen=True)
class Visit:
    """The session behind a participant link, as the pages need it."""

    token: str
    session_id: int
    study_id: int
    status: str
    advice_budget: int
    advice_given: int
    texts: dict[str, str]
    sort_rule: Any
    consented: bool = False
    ready: bool = False
    shown_texts: dict[str, str] | None = None
    """The stored texts version this participant consented to (None before consent)."""
    check: CheckState = field(default_factory=lambda: CheckState(required=False))
    questionnaire_due: bool = False
    """The design asks a questionnaire and this participant has not submitted it."""
    outcome: str | None = None
    """How the visit ended (`Outcome`); None while it goes on, and always in a lab study."""
    design: dict[str, Any] | None = None
    """The online study's design (None in a lab study)."""
    strategy: str = "early"
    """When the robot asks (`learner.strategies`): what `{advice_plan}` tells the person."""
    interval: int | None = None
    """The alternating strategy's: one advised action in every `interval`."""
    task: str = "sorting"
    """The run's task (`tasks`): the advice page's buttons and view, the pages' words."""
    feedback: str = "advice"
    """The run's kind of feedback (`RunSpec.feedback`): the page asks for advice, or for
    ratings of the learner's own actions (evaluative)."""
    rating_time_out_s: float = 10.0
    """Evaluative feedback: the time a rating may take before the learner goes on."""

    @property
    def the_task(self) -> Task:
        return get_task(self.task)

    @property
    def agent(self) -> str:
        """What the pages call the learner ("robot", "agent")."""
        return self.the_task.agent

    @property
    def online(self) -> bool:
        """The study has a design (an online study): check, questionnaire, an outcome page."""
        return self.design is not None

    @property
    def check_pending(self) -> bool:
        """A comprehension check must be passed before the advice starts."""
        return self.check.required and not self.check.passed

    @property
    def started(self) -> bool:
        """Consent given and the induction done: the participant may advise."""
        return self.consented and self.ready

    @property
    def done(self) -> bool:
        return self.advice_given >= self.advice_budget or self.status == Status.finished

    def advice_plan(self) -> str:
        """When this person advises, as the robot's strategy has it (`{advice_plan}`); under
        evaluative feedback, when they rate its moves."""
        n = self.advice_budget
        if self.feedback == "evaluative":
            return self._rating_plan()
        if self.strategy == "early" or (self.strategy == "alternating" and self.interval == 1):
            return (
                # the next, not its first: early advice ends the random practice, which
                # the robot has mostly done before the person's first turn
                f"For the next {n} actions, "
                "**you** choose what it does. After that it continues on its own"
            )
        if self.strategy == "alternating":
            return (
                f"**You** choose {n} of its actions, one action in every {self.interval or 2}: it "
                "takes the actions in between on its own, so you will see it move by itself "
                "between your choices. After your last choice it continues on its own"
            )
        return (
            f"**You** choose {n} of its actions, at moments the {self.agent} picks itself; in "
            "between and after, it acts on its own"
        )

    def _rating_plan(self) -> str:
        n = self.advice_budget
        seconds = f"{self.rating_time_out_s:g} seconds"
        if self.strategy == "early" or (self.strategy == "alternating" and self.interval == 1):
            when = f"For the next {n} actions, the {self.agent} chooses and **you** rate"
        elif self.strategy == "alternating":
            when = (
                f"For {n} of its actions, one in every {self.interval or 2}, **you** rate "
                f"what the {self.agent} chose"
            )
        else:
            when = f"For {n} of its actions, at moments it picks itself, **you** rate"
        return (
            f"{when} each move: **Good** or **Bad**, within {seconds} (no answer is fine: it "
            "goes on). After that it continues on its own"
        )

    @property
    def idle_limit_s(self) -> float | None:
        """An online study's limit on waiting for an answer (the visit ends `timed_out`);
        None in a lab study, whose session waits and resumes when the person comes back."""
        return None if self.design is None else float(self.design.get("idle_limit_s", 600))

    def time_rule(self) -> str:
        """How long a choice may take (`{time_rule}`): no limit in a lab study; an online
        study ends a visit that gives no answer for its design's `idle_limit_s`."""
        if self.feedback == "evaluative":
            return (
                f"You have **{self.rating_time_out_s:g} seconds** for each rating; without one "
                f"the {self.agent} goes on by itself."
            )
        if self.design is None:
            return "There is **no time limit**. Take the time you need for each choice."
        minutes = max(1, round((self.idle_limit_s or 600) / 60))
        return (
            "Take the time you need for each choice. Only if you give no answer for "
            f"{minutes} minute{'s' if minutes != 1 else ''} does the study end early."
        )

    def after_advice(self) -> str:
        """What follows the last choice (`{after_advice}`): in a lab study the robot's
        progress to watch; in an online study its questions, if it asks any, and the
        completion code (the visit ends there: no progress page)."""
        if self.design is None:
            return (
                f"After your last choice, the {self.agent} carries on learning on its own, and you "
                "can watch its progress."
            )
        if self.design.get("questionnaire"):
            return (
                "After your last choice, you answer a few questions about the study, and then "
                "you receive your completion code."
            )
        return "After your last choice, you receive your completion code."

    def resolved_texts(self) -> dict[str, str]:
        """Every page text as it is shown now: the study's or the default, filled in."""
        task = self.the_task
        fill = {
            **task_words(task),
            "{advice_budget}": str(self.advice_budget),
            "{sorting_rule}": describe_rule(self.sort_rule),
            "{advice_plan}": self.advice_plan(),
            "{time_rule}": self.time_rule(),
            "{after_advice}": self.after_advice(),
        }
        out = {}
        for key in TEXT_KEYS:
            raw = self.texts.get(key) or default_text(key, task, self.feedback)
            for name, value in fill.items():
                raw = raw.replace(name, value)
            out[key] = raw
        return out

    def text(self, key: str) -> Markup:
        assert key in TEXT_KEYS, key
        if self.shown_texts is not None and key in self.shown_texts:
            return render_text(self.shown_texts[key])
        return render_text(self.resolved_texts()[key])


def _visit(request: Request, token: str) -> Visit | None:
    with request.app.state.session_factory() as db:
        session = session_for_token(db, token)
        if session is None:
            return None
        given = db.scalar(select(func.count()).where(Advice.session_id == session.id)) or 0
        given += judgements_given(db, session.id)  # a rating session's turns
        version = session.texts_version
        questionnaire = visit_service.questionnaire_progress(db, session)
        return Visit(
            token=token,
            session_id=session.id,
            study_id=session.study_id,
            status=request.app.state.manager.status(session.id),
            advice_budget=session.spec.advice_budget,
            advice_given=int(given),
            texts=_texts(session.study.texts, session.study.design, session.condition),
            sort_rule=session.spec.sort_rule,
            task=session.spec.task,
            consented=session.consented_at is not None,
            ready=session.induction_done_at is not None,
            shown_texts=(
                dict(version.texts)
                if version is not None and session.consented_at is not None
                else None
            ),
            check=check_state(visit_service.check_progress(db, session)),
            questionnaire_due=questionnaire.required and questionnaire.submitted_at is None,
            outcome=session.outcome,
            design=session.study.design,
            strategy=session.spec.strategy,
            interval=session.spec.strategy_options.interval,
            feedback=session.spec.feedback,
            rating_time_out_s=session.spec.rating_time_out_s,
        )


def _texts(
    study: dict[str, Any] | None, design: dict[str, Any] | None, condition: str | None
) -> dict[str, str]:
    """The study's texts, a condition's own over them."""
    texts = {k: str(v) for k, v in (study or {}).items()}
    if design is not None and condition is not None:
        texts.update(design["conditions"].get(condition, {}).get("texts", {}))
    return texts


visit_for_token = _visit


async def _load(request: Request, token: str, warm_up: bool = True) -> Visit | None:
    """The visit; opening the link starts the session's random pretraining (the robot
    practises while the participant reads), advice waits for consent and induction. A visit
    that ended (an outcome) starts nothing."""
    visit = await run_in_threadpool(_visit, request, token)
    waiting = visit is not None and visit.status in (Status.created, Status.abandoned)
    if visit is not None and warm_up and waiting and visit.outcome is None:
        await request.app.state.manager.welcome(visit.session_id)
        visit = await run_in_threadpool(_visit, request, token)
    return visit


def _page(
    request: Request, name: str, visit: Visit | None, title: str | None = None, **context: Any
) -> HTMLResponse:
    """A participant page, titled by the visit's texts (or `title`: a study's, before a
    session exists)."""
    if title is None:
        title = (visit.text("title") if visit is not None else Markup("IDeepRL")).striptags()
    return templates.TemplateResponse(
        request, name, {"visit": visit, "site_title": title, **context}
    )


participant_page = _page


def study_title(texts: dict[str, Any] | None, task: str | None = "sorting") -> str:
    """A study's page title (its `title` text, else its task's), before any session;
    `task` None: its conditions' tasks differ, and the title names none."""
    given = (texts or {}).get("title")
    if given:
        raw = str(given)
    elif task is None:
        raw = "Help a learning program learn"
    else:
        the_task = get_task(task)
        raw = default_text("title", the_task)
        for name, value in task_words(the_task).items():
            raw = raw.replace(name, value)
    return render_text(raw).striptags()


def _error(request: Request) -> HTMLResponse:
    response = _page(request, "participant/error.html", None)
    response.status_code = 403
    return response


def _go(visit: Visit, where: str) -> RedirectResponse:
    return RedirectResponse(f"/p/{visit.token}/{where}", status_code=303)


def _resume_point(visit: Visit) -> str:
    if visit.outcome is not None:
        return "end"
    if not visit.consented:
        return "consent"
    if not visit.ready:
        return "check" if visit.check.tries_used else "induction/1"
    if visit.done:
        return "questionnaire" if visit.online else "thanks"
    return "advise"


@router.get("/p/{token}")
async def entry(request: Request, token: str) -> Response:
    """The participant link: continue where this participant is."""
    visit = await _load(request, token)
    return _error(request) if visit is None else _go(visit, _resume_point(visit))


@router.get("/p/{token}/consent")
async def consent(request: Request, token: str) -> Response:
    visit = await _load(request, token)
    if visit is None:
        return _error(request)
    if visit.consented or visit.outcome is not None:
        return _go(visit, _resume_point(visit))
    texts = visit.resolved_texts()
    version = await run_in_threadpool(_texts_version, request, visit.study_id, texts)
    return _page(
        request,
        "participant/consent.html",
        visit,
        body=render_text(texts["consent"]),
        texts_version=version,
    )


def _texts_version(request: Request, study_id: int, texts: dict[str, str]) -> int:
    with request.app.state.session_factory() as db:
        return consent_service.texts_version(db, study_id, texts).id


@router.post("/p/{token}/consent")
async def decide(
    request: Request,
    token: str,
    decision: str = Form(default=""),
    texts_version: int | None = Form(default=None),
) -> Response:
    """The consent form: 'agree' or 'decline', with the texts version the page showed. In
    an online study a decline ends the visit at once (its worker stopped, its place freed)
    and shows the declined code."""
    decided = await run_in_threadpool(_decide, request, token, decision, texts_version)
    if isinstance(decided, Response):
        return decided
    if decision == "agree":
        return RedirectResponse(f"/p/{token}/induction/1", status_code=303)
    if decided is not None:
        await end_visit(request.app.state.manager, decided, Outcome.declined)
        return RedirectResponse(f"/p/{token}/end", status_code=303)
    return RedirectResponse(f"/p/{token}/declined", status_code=303)


def _decide(
    request: Request, token: str, decision: str, texts_version: int | None
) -> Response | int | None:
    """Record the decision; a page to go to instead, or the session's id when it is an
    online study's visit (None: a lab session)."""
    with request.app.state.session_factory() as db:
        session = session_for_token(db, token)
        if session is None:
            return _error(request)
        if decision not in ("agree", "decline"):
            return RedirectResponse(f"/p/{token}/consent", status_code=303)
        if session.outcome is not None:
            return RedirectResponse(f"/p/{token}/end", status_code=303)
        try:
            consent_service.record_decision(db, session, decision == "agree", texts_version)
        except (Conflict, Invalid):  # a stale page: consent given meanwhile, a bad version
            db.rollback()
            return RedirectResponse(f"/p/{token}", status_code=303)
        return session.id if session.condition is not None else None


@router.get("/p/{token}/declined")
def declined(request: Request, token: str) -> Response:
    visit = _visit(request, token)
    return _error(request) if visit is None else _page(request, "participant/declined.html", visit)


@router.get("/p/{token}/induction/{step}")
async def induction(request: Request, token: str, step: int) -> Response:
    visit = await _load(request, token)
    if visit is None:
        return _error(request)
    if not visit.consented or visit.outcome is not None:
        return _go(visit, _resume_point(visit))
    if not 1 <= step <= 3:
        return _go(visit, "induction/1")
    return _page(
        request,
        "participant/induction.html",
        visit,
        step=step,
        titles=induction_titles(visit.the_task),
        body=visit.text(f"induction_{step}"),
    )


@router.get("/p/{token}/advise")
def advise(request: Request, token: str) -> Response:
    visit = _visit(request, token)
    if visit is None:
        return _error(request)
    if not visit.started or visit.done or visit.outcome is not None:
        return _go(visit, _resume_point(visit))
    return _page(
        request,
        "participant/advise.html",
        visit,
        scene_src=scene_src(request, get_task(visit.task)),
        task=get_task(visit.task),
        task_keys=_task_keys,
    )


def _task_keys(task: Task) -> dict[str, int]:
    """The advice page's keys for a task's actions (lower case, as the page reads them),
    and the digits 1 to n for actions 1 to n."""
    keys = {str(i + 1): i for i in range(min(task.n_actions, 9))}
    keys.update({a.key.lower(): i for i, a in enumerate(task.actions) if a.key})
    return keys


@router.get("/p/{token}/thanks")
def thanks(request: Request, token: str) -> Response:
    visit = _visit(request, token)
    if visit is None:
        return _error(request)
    if not visit.started or not visit.done or visit.online or visit.outcome is not None:
        return _go(visit, _resume_point(visit))
    return _page(request, "participant/thanks.html", visit, body=visit.text("thanks"))


@router.get("/p/{token}/check")
async def check(request: Request, token: str) -> Response:
    """An online study's comprehension check, between the induction and the advice."""
    visit = await _load(request, token)
    if visit is None:
        return _error(request)
    if visit.outcome is not None or not visit.consented or visit.started:
        return _go(visit, _resume_point(visit))
    if not visit.check.required:
        return _go(visit, "induction/3")
    return _page(request, "participant/check.html", visit, check=visit.check)


@router.get("/p/{token}/questionnaire")
async def questionnaire(request: Request, token: str) -> Response:
    """An online study's questionnaire after the advice; a design without one completes
    the visit here (the server already did with the last advice)."""
    visit = await run_in_threadpool(_visit, request, token)
    if visit is None:
        return _error(request)
    if visit.outcome is not None or not visit.started or not visit.done or not visit.online:
        return _go(visit, _resume_point(visit))
    if not visit.questionnaire_due:
        await end_visit(request.app.state.manager, visit.session_id, Outcome.completed)
        return _go(visit, "end")
    sections = await run_in_threadpool(_sections, request, token)
    return _page(
        request,
        "participant/questionnaire.html",
        visit,
        sections=sections,
        prefer_not_to_say=PREFER_NOT_TO_SAY,
    )


def _sections(request: Request, token: str) -> list[Section]:
    with request.app.state.session_factory() as db:
        session = session_for_token(db, token)
        assert session is not None, "the visit was just read"
        return visit_service.questionnaire_progress(db, session).sections


END_PAGES = {
    Outcome.completed: ("Thank you", "You have finished the study."),
    Outcome.declined: ("You chose not to take part", "We recorded only that you declined."),
    Outcome.excluded: (
        "Thank you for your time",
        "Your answers to the questions about the task did not match, so the study ends here.",
    ),
    Outcome.timed_out: (
        "Your time ran out",
        "The study waited for you longer than it can, so it has ended.",
    ),
    Outcome.full: (
        "The study is full",
        "This study has all the participants it can take, so your visit ends here. Thank "
        "you for your interest.",
    ),
}
"""Heading and message of each outcome's page."""


def end_page(
    request: Request,
    visit: Visit | None,
    design: StudyDesign,
    outcome: Outcome,
    params: dict[str, str] | None = None,
    title: str | None = None,
) -> Response:
    """An outcome's page: its code, and a redirect to the panel's URL for it (when set),
    filled in with the arrival's panel parameters `params`; `title` without a visit."""
    heading, message = END_PAGES[outcome]
    return _page(
        request,
        "participant/end.html",
        visit,
        title,
        outcome=outcome.value,
        heading=heading,
        message=message,
        code=design.code(outcome),
        return_url=design.return_url(outcome, params),
        delay_s=design.panel.return_delay_s,
    )


@router.get("/p/{token}/end")
def end(request: Request, token: str) -> Response:
    """Where every visit of an online study ends: the outcome's code and return link."""
    visit = _visit(request, token)
    if visit is None:
        return _error(request)
    if visit.outcome is None or visit.design is None:
        return _go(visit, _resume_point(visit))
    design = StudyDesign.model_validate(visit.design)
    return end_page(request, visit, design, Outcome(visit.outcome), _panel_params(request, token))


def _panel_params(request: Request, token: str) -> dict[str, str]:
    """The panel parameters the participant arrived with (none without a panel id)."""
    with request.app.state.session_factory() as db:
        session = session_for_token(db, token)
        assert session is not None
        query = select(PanelId.params).where(PanelId.participant_id == session.participant_id)
        return dict(db.scalar(query) or {})


def scene_src(request: Request, task: Task | None = None) -> str:
    """viser's client under /viewer/ of this server, with the task's camera for people (the
    sorting robot's where it names none); the page adds the websocket (`/viewer/p/TOKEN` on
    the same host, ws or wss as loaded)."""
    base = request.app.state.settings.viewer_public_url or "/viewer/"
    base = base.rstrip("/") + "/"
    camera = task.camera if task is not None and task.camera is not None else VIEWER_CAMERA
    params = "&".join(f"{k}={v}" for k, v in viser_camera_params(camera).items())
    return f"{base}?hideViserLogo&{params}"


def describe_rule(spec: Any) -> str:
    """The sorting rule in words, e.g. 'put the blue objects on the right table and the red
    objects on the left table'."""
    rule = sim.SortRule.parse(spec)
    objects = [(shape, color) for shape in sim.SHAPES for color in sim.COLORS]
    parts = []
    for side in ("right", "left"):
        chosen = {o for o in objects if rule.side(*o) == side}
        if chosen:
            parts.append(f"{_describe_group(chosen, objects)} on the {side} table")
    return "put " + " and ".join(parts)


def _describe_group(chosen: set[tuple[str, str]], objects: list[tuple[str, str]]) -> str:
    for color in sim.COLORS:
        if chosen == {o for o in objects if o[1] == color}:
            return f"the {color} objects"
    shapes = [s for s in sim.SHAPES if {(s, c) for c in sim.COLORS} <= chosen]
    if chosen == {o for o in objects if o[0] in shapes}:
        return "the " + _join([f"{s}s" for s in shapes])
    return "the " + _join([f"{color} {shape}" for shape, color in sorted(chosen)])


def _join(words: list[str]) -> str:
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]


def render_text(text: str) -> Markup:
    """Plain text with a little structure: blank lines between paragraphs, `- ` bullets,
    `## ` headings, `**bold**`. Everything is escaped; nothing else is interpreted."""
    out: list[str] = []
    paragraph: list[str] = []
    bullets: list[str] = []

    def flush() -> None:
        if paragraph:
            out.append(f"<p>{_inline(' '.join(paragraph))}</p>")
            paragraph.clear()
        if bullets:
            out.append("<ul>" + "".join(f"<li>{_inline(b)}</li>" for b in bullets) + "</ul>")
            bullets.clear()

    for raw in text.strip().splitlines():
        line = raw.strip()
        if not line:
            flush()
        elif line.startswith("## "):
            flush()
            out.append(f"<h2>{_inline(line[3:])}</h2>")
        elif line.startswith("- "):
            if paragraph:
                flush()
            bullets.append(line[2:])
        elif bullets and raw[:1].isspace():
            bullets[-1] += " " + line  # a bullet continued on an indented line
        else:
            if bullets:
                flush()
            paragraph.append(line)
    flush()
    return Markup("\n".join(out))


def _inline(text: str) -> str:
    return re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", html.escape(text))
