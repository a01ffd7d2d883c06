"""A rehearsal of a study's load: fitted advisors answer human sessions through the
participant's own HTTP calls (what `web/static/advise.js` does: consent, the study's
comprehension check where it asks one, the induction's Start, long-polled state, advice
with its decision time), waiting their drawn decision
times, with the 3-D view's websocket open as the page keeps it (`/viewer/p/TOKEN`, every
scene message read), so the server meets the traffic, the waits and the early leavers of
real people.

The simulated person sees only what the page shows and advises with
`learner.fitted.FittedAdvisor` in the model's task: for the sorting robot, the arm's
station and what it holds (in the participant state), so its advice is right or wrong as
the fitted people's were there; for a task shown as frames, no ground truth, so it names
actions as often as the fitted people did. It leaves early as often as they did
(`FittedAdvisor.stop_after`). Under evaluative feedback it rates the move the learner made
instead: Good when it is the action it would have advised, else Bad, sent after the drawn
decision time, or not at all when that time is longer than the turn's time-out (the turn
lapses, as a person's). With a model fitted to ratings (`learner.fitted_ratings`) it rates
as the fitted evaluators did instead (`FittedEvaluator`: their errors on right and wrong
moves, their silent turns, their times); such a person advises nobody. A client of the
server's HTTP API only: it runs anywhere the participant links reach.

Through an online study's link (`join`) a simulated participant arrives as a panel's
would, with its own panel id, and goes through the whole visit: the comprehension check
and, after its turns, the questionnaire (each item answered in the middle of its scale).
It answers the check only where it knows the right answers: the built-in questions (the
task's own, the sorting robot's under the sort rule, what to do when asked for a rating),
each known only where it is asked word for word, and the study's own questions where the
rehearsal is given the study's check (`design_check`: from the design's file, or read
through the researcher API, `study_check`). It never guesses: a check that asks a
question it does not know stops it before it answers (`UnknownCheck`, naming the
questions). A participant drawn to fail the check (`fail_check`) answers every question
wrong on every try, and the check excludes it as it would a person.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit

import httpx

from learner.fitted import FittedAdvisor
from learner.fitted_ratings import AnyFitted, FittedEvaluator, FittedEvaluatorModel
from learner.records import TRAINING, stage_of
from sim.rules import SortRule
from study.schemas.design import StudyDesign
from study.schemas.visit import CheckQuestion, CheckSpec, default_questions
from study.services.visit import expected_answer, rating_question, task_questions
from tasks import Task, get_task

ENDED = ("finished", "stopped", "interrupted", "abandoned", "failed")
PAGE = 1000
"""Items asked for at once from the researcher API's lists."""
Shown = tuple[str, str, tuple[tuple[str, str], ...]]
"""A check question as the participant sees it: id, text, (value, label) of each choice."""


@dataclass(frozen=True)
class Rehearsed:
    """What one simulated participant did."""

    token_tail: str
    """The link's last characters (never the whole token: it opens the session)."""
    advice: int
    decision_times_s: list[float]
    left_early: bool
    status: str
    """The session's status when the participant stopped."""
    viewer_messages: int = 0
    """Scene messages the 3-D view's websocket delivered (0 without the view)."""
    viewer_bytes: int = 0
    feedback: str = "advice"
    """The kind of its turns: advice, or evaluative (ratings of the learner's moves)."""
    lapsed: int = 0
    """Rating turns left without an answer (their time-out passed first)."""
    check_tries: int = 0
    """Tries at an online study's comprehension check (0: none asked)."""
    questionnaire: bool = False
    """It submitted an online study's questionnaire (which completes the visit)."""


class _Viewer(threading.Thread):
    """The page's 3-D view: viser's websocket through the server's relay, read until closed."""

    def __init__(self, base_url: str, token: str) -> None:
        super().__init__(daemon=True)
        self.url = base_url.replace("http", "ws", 1).rstrip("/") + f"/viewer/p/{token}"
        self.messages = self.bytes = 0
        self.error: str | None = None
        self._done = threading.Event()

    def run(self) -> None:
        import viser
        from websockets.exceptions import ConnectionClosed
        from websockets.sync.client import connect
        from websockets.typing import Subprotocol

        try:
            with connect(
                self.url, subprotocols=[Subprotocol(f"viser-v{viser.__version__}")], open_timeout=30
            ) as socket:
                while not self._done.is_set():
                    try:
                        message = socket.recv(timeout=0.5)
                    except TimeoutError:
                        continue
                    self.messages += 1
                    self.bytes += len(message)
        except ConnectionClosed:
            pass
        except (OSError, ValueError) as error:
            self.error = str(error)

    def close(self) -> None:
        self._done.set()
        self.join(timeout=5)


def _info(state: dict[str, Any]) -> dict[str, Any]:
    """The ground truth the sorting robot's page shows: station and held object."""
    held = state.get("held") or {}
    return {
        "station": state.get("station") or "center",
        "held": f"{held['shape']}/{held['color']}" if held else "",
        "held_color": held.get("color", ""),
        "held_shape": held.get("shape", ""),
    }


def rehearse(
    base_url: str,
    token: str,
    model: AnyFitted,
    sort_rule: Any = "color",
    seed: int | None = None,
    speed: float = 1.0,
    timeout_s: float = 600.0,
    viewer: bool = True,
    design_check: CheckSpec | None = None,
    fail_check: bool = False,
    on_check: Callable[[], None] | None = None,
) -> Rehearsed:
    """One simulated participant through the session of `token`, until its advice is
    over, it leaves early, or the session ends. `speed` > 1 divides the waits (a quick
    rehearsal); the decision time sent is the drawn one. `viewer`: keep the 3-D view's
    websocket open meanwhile, as the page does (a task with a live 3-D view). A model
    fitted to ratings rates; one fitted to advice advises, and rates as it would advise.
    `design_check`: the study design's check, whose own questions it then answers right
    (without it, a check asking any question other than the built-in ones raises
    `UnknownCheck` before it is answered); `fail_check`: it answers the check wrong on
    every try (and is excluded); `on_check` is called once the check is answered (or
    none is asked)."""
    task = get_task(model.task)
    advisor: FittedAdvisor | FittedEvaluator
    if isinstance(model, FittedEvaluatorModel):
        options = _options(task, sort_rule)
        advisor = FittedEvaluator(model, seed=seed, task=task, task_options=options)
    elif model.task == "sorting":
        advisor = FittedAdvisor(model, sort_rule, seed)
    else:
        advisor = FittedAdvisor(model, seed=seed, task=task)
    view = _Viewer(base_url, token) if viewer and task.live_view else None
    headers = {"Authorization": f"Bearer {token}"}
    times: list[float] = []
    kind, lapsed = "advice", 0
    with httpx.Client(base_url=base_url, headers=headers, timeout=60) as client:
        shown = _ok(client.get("/api/participant/consent"))
        _ok(client.post("/api/participant/consent", json={"agree": True,
                        "texts_version": shown["texts_version"]}))  # fmt: skip
        check = _ok(client.get("/api/participant/check"))
        asked = check["required"] and not check["passed"]  # (passed: a participant back)
        known = _known(task, sort_rule, design_check)
        tries, passed = _take_check(client, check, known, fail_check) if asked else (0, True)
        if on_check is not None:
            on_check()
        if not passed:  # every try wrong: the visit ended `excluded`
            return Rehearsed(token[-4:], 0, [], False, "excluded", check_tries=tries)
        state = _ok(client.post("/api/participant/start"))
        if view is not None:
            view.start()
        budget = int(state["advice_budget"])
        stop_after = advisor.stop_after(budget) if isinstance(advisor, FittedAdvisor) else None
        deadline = time.monotonic() + timeout_s
        while state["status"] not in ENDED and time.monotonic() < deadline:
            if stop_after is not None and len(times) >= stop_after:
                break  # this person leaves: the session's idle limit will abandon it
            if state["advice_wanted"] and state.get("rated_action") is not None:
                kind = "evaluative"
                answered, state = _rate(client, advisor, task, state, speed)
                if answered is None:
                    lapsed += 1
                else:
                    times.append(answered)
                continue
            if state["advice_wanted"] and state["advice_index"] is not None:
                if not isinstance(advisor, FittedAdvisor):
                    raise RuntimeError(
                        "the model was fitted to ratings and this session asks for advice: "
                        "rehearse it with a model fitted to advice"
                    )
                action = _would_advise(advisor, task, state)
                drawn = advisor.last_decision_time_s or 0.0
                time.sleep(drawn / speed)
                body = {"advice_index": state["advice_index"], "action": action,
                        "decision_time_s": drawn}  # fmt: skip
                receipt = _ok(client.post("/api/participant/advice", params={"wait": 20},
                                          json=body))  # fmt: skip
                if not receipt["duplicate"]:
                    times.append(drawn)
                state = receipt["state"] or _ok(client.get("/api/participant/state"))
                continue
            if state["advice_left"] == 0 and state["advice_given"] > 0:
                break  # the advice is over; the learner trains on without the person
            state = _ok(client.get("/api/participant/state",
                                   params={"after": state["version"], "timeout": 20}))  # fmt: skip
        left_early = stop_after is not None and len(times) >= stop_after
        answered = not left_early and _questionnaire(client, deadline)
    if view is not None:
        view.close()
    return Rehearsed(
        token_tail=token[-4:],
        advice=len(times),
        decision_times_s=times,
        left_early=left_early,
        status=str(state["status"]),
        viewer_messages=view.messages if view is not None else 0,
        viewer_bytes=view.bytes if view is not None else 0,
        feedback=kind,
        lapsed=lapsed,
        check_tries=tries,
        questionnaire=answered,
    )


class UnknownCheck(RuntimeError):
    """A comprehension check that asks questions the rehearsal is not told the answers to:
    it stops there rather than guess them."""

    def __init__(self, questions: list[tuple[str, str]]) -> None:
        self.questions = questions
        """(id, text) of each question it cannot answer."""
        asked = "; ".join(f"{id} ({text!r})" for id, text in questions)
        super().__init__(
            f"the study's comprehension check asks {len(questions)} question(s) this "
            f"rehearsal is not told the right answers to, and it does not guess them: {asked}"
        )


def _base(link: str, marker: str) -> tuple[str, str]:
    """(the server's base URL, what follows `marker` in the link's path)."""
    parts = urlsplit(link)
    prefix, _, rest = parts.path.rpartition(marker)
    return f"{parts.scheme}://{parts.netloc}{prefix}", rest


def join(link: str, panel_id: str, panel_param: str = "PROLIFIC_PID") -> tuple[str, str]:
    """Arrive through an online study's link as the panel's participant `panel_id`: (the
    server's base URL, the session's token), as the link's redirect gives them."""
    base, _ = _base(link, "/join/")
    query = {panel_param: panel_id, "STUDY_ID": "rehearsal", "SESSION_ID": f"r-{panel_id}"}
    with httpx.Client(timeout=60) as client:
        response = client.get(link, params=query)
    target = response.headers.get("location", "")
    if response.status_code != 303 or "/p/" not in target:
        raise RuntimeError(
            f"the study link did not admit {panel_id} ({response.status_code}): is it an "
            "online study's join link with places left?"
        )
    return base, target.rpartition("/p/")[2]


def study_check(link: str, api_key: str) -> CheckSpec | None:
    """The comprehension check of the study a link belongs to (an online study's join link,
    or a participant link `.../p/TOKEN`), read from its design through the researcher API
    with the researcher's key: None where that study asks none (a lab study, or a design
    without a check). `RuntimeError` says why it cannot be read (the key refused, no study
    with that join link)."""
    joining = "/join/" in urlsplit(link).path
    base, key = _base(link, "/join/" if joining else "/p/")
    with httpx.Client(base_url=base, headers={"X-API-Key": api_key}, timeout=60) as client:
        for study in _every(client, "/api/studies"):
            design = study.get("design")
            if design is None:
                continue  # a lab study: its sessions ask no check
            if joining:
                found = (study.get("join_url") or "").rpartition("/join/")[2] == key
            else:
                found = any(
                    (s.get("participant_url") or "").rpartition("/p/")[2] == key
                    for s in _every(client, f"/api/studies/{study['id']}/sessions")
                )
            if found:
                return StudyDesign.model_validate(design).check
    if joining:
        raise RuntimeError(f"no online study on {base} has the join link {link}")
    return None  # the session is no online study's: no check


def _every(client: httpx.Client, path: str) -> list[dict[str, Any]]:
    """Every item of a paged list of the researcher API."""
    items: list[dict[str, Any]] = []
    while True:
        response = client.get(path, params={"limit": PAGE, "offset": len(items)})
        if response.status_code in (401, 403):
            raise RuntimeError(
                f"the server refused the researcher key ({response.status_code}): give the "
                "key it was started with (--api-key, or IDEEPRL_API_KEY)"
            )
        _ok(response)  # a status other than 200 raises, saying what the server answered
        page: list[dict[str, Any]] = response.json()
        items += page
        if len(page) < PAGE:
            return items


def _shown(q: CheckQuestion) -> Shown:
    """A question as the participant's check shows it (never its answer)."""
    return q.id, q.text, tuple((c.value, c.label) for c in q.choices)


def _asked(q: dict[str, Any]) -> Shown:
    """A question of `GET /api/participant/check`, as `_shown` gives one."""
    return q["id"], q["text"], tuple((c["value"], c["label"]) for c in q["choices"])


def _known(task: Task, sort_rule: Any, design_check: CheckSpec | None) -> dict[Shown, str]:
    """The check's questions whose right answers the rehearsal knows, as the participant
    sees them: the task's own questions, the rating question, the sorting robot's under
    the sort rule, and the study's own (`design_check`: a side of the table under the sort
    rule where the question asks one)."""
    built_in = [*task_questions(task), rating_question(task.agent)]
    if task.name == "sorting":
        built_in += default_questions()
    questions = [*built_in, *(design_check.questions if design_check is not None else [])]
    rule = SortRule.parse(sort_rule)
    return {_shown(q): expected_answer(q, rule) for q in questions}


def _take_check(
    client: httpx.Client, check: dict[str, Any], known: dict[Shown, str], fail: bool
) -> tuple[int, bool]:
    """The comprehension check, answered right, or, to `fail` it, wrong on every try: the
    tries it took and whether it passed. `UnknownCheck`, before any answer, where it asks a
    question whose answer is not known."""
    unknown = [q for q in check["questions"] if _asked(q) not in known]
    if unknown:
        raise UnknownCheck([(q["id"], q["text"]) for q in unknown])
    tries = 0
    while True:
        answers = {}
        for q in check["questions"]:
            right = known[_asked(q)]
            values = [c["value"] for c in q["choices"]]
            answers[q["id"]] = next(v for v in values if v != right) if fail else right
        result = _ok(client.post("/api/participant/check", json={"answers": answers}))
        tries += 1
        if result["passed"] or result["excluded"]:
            return tries, bool(result["passed"])
        if not fail:
            raise RuntimeError(
                "the check marked wrong the answers the rehearsal knows as right: "
                f"{', '.join(result['wrong'])} (is the sort rule the study's?)"
            )


def fails_check(index: int, share: float) -> bool:
    """Whether participant `index` (from 0) of a rehearsal is one of the `share` that fail
    the check: spread evenly, so that of the first n, floor(n x share) fail."""
    eps = 1e-9  # 10 x 0.3 is 3.0000000000000004, 3 x 0.1 is 0.30000000000000004
    return int((index + 1) * share + eps) > int(index * share + eps)


def _questionnaire(client: httpx.Client, deadline: float) -> bool:
    """An online study's questionnaire once it may be answered, every item in the middle of
    its scale; whether it was submitted (False: none asked)."""
    state = _ok(client.get("/api/participant/questionnaire"))
    while state["required"] and not state["available"] and time.monotonic() < deadline:
        time.sleep(0.5)
        state = _ok(client.get("/api/participant/questionnaire"))
    if not state["required"] or state["submitted_at"] is not None or not state["available"]:
        return False
    answers = {
        section["instrument"]: {item["id"]: _middle(item) for item in section["items"]}
        for section in state["sections"]
    }
    _ok(client.post("/api/participant/questionnaire", json={"answers": answers}))
    return True


def _middle(item: dict[str, Any]) -> Any:
    if item["kind"] == "likert":
        return item["points"] // 2 + 1
    if item["kind"] == "choice":
        return item["choices"][0]
    if item["kind"] == "number":
        low, high, step = item["minimum"], item["maximum"], item.get("step") or 1
        return low + round((high - low) / 2 / step) * step
    return "rehearsal"


def _rate(
    client: httpx.Client,
    advisor: FittedAdvisor | FittedEvaluator,
    task: Task,
    state: dict[str, Any],
    speed: float,
) -> tuple[float | None, dict[str, Any]]:
    """One rating turn: (the decision time sent, or None for a turn left to lapse; the
    state after it)."""
    index = state["advice_index"]
    rating = _rating(advisor, task, state)
    drawn = advisor.last_decision_time_s or 0.0
    left = float(state.get("rating_left_s") or 0.0)
    if rating is None or drawn / speed >= left:  # silent, or too slow: no answer
        while state["advice_index"] == index and state["status"] not in ENDED:
            state = _ok(client.get("/api/participant/state",
                                   params={"after": state["version"], "timeout": 20}))  # fmt: skip
        return None, state
    time.sleep(drawn / speed)
    body = {"advice_index": index, "rating": rating, "decision_time_s": drawn}
    receipt = _ok(client.post("/api/participant/rating", params={"wait": 20}, json=body))
    return drawn, receipt["state"] or _ok(client.get("/api/participant/state"))


def _rating(
    advisor: FittedAdvisor | FittedEvaluator, task: Task, state: dict[str, Any]
) -> str | None:
    """The simulated person's rating of the move shown: good, bad, or None (no answer)."""
    if isinstance(advisor, FittedAdvisor):  # rates as it would advise
        return "good" if _would_advise(advisor, task, state) == state["rated_action"] else "bad"
    seen = _info(state) if task.live_view else None
    stage = stage_of(state["stage"]) if state.get("stage") else TRAINING
    judgement = advisor.rate(seen, stage, int(state["rated_action"]))
    return None if judgement is None else ("good" if judgement > 0 else "bad")


def _options(task: Task, sort_rule: Any) -> dict[str, Any] | None:
    """The options the simulated person judges by: the sorting robot's rule, else none."""
    return {"sort_rule": SortRule.parse(sort_rule).to_spec()} if task.name == "sorting" else None


def _would_advise(advisor: FittedAdvisor, task: Task, state: dict[str, Any]) -> int:
    """The action the simulated person names in this state (what the page shows)."""
    seen = _info(state) if task.live_view else None
    stage = stage_of(state["stage"]) if state.get("stage") else TRAINING
    action = advisor.advise_in(seen, stage)
    assert isinstance(action, int), "made without a budget: it never leaves itself"
    return action


def _ok(response: httpx.Response) -> dict[str, Any]:
    if response.status_code != 200:
        raise RuntimeError(
            f"{response.request.method} {response.request.url.path}: "
            f"{response.status_code} {response.text[:300]}"
        )
    data: dict[str, Any] = response.json()
    return data
