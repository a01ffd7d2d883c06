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
(`FittedAdvisor.stop_after`). A client of
the server's HTTP API only: it runs anywhere the participant links reach.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any

import httpx

from learner.fitted import FittedAdvisor, FittedModel
from learner.records import TRAINING, stage_of
from study.services.visit import task_questions
from tasks import Task, get_task

ENDED = ("finished", "stopped", "interrupted", "abandoned", "failed")


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
    model: FittedModel,
    sort_rule: Any = "color",
    seed: int | None = None,
    speed: float = 1.0,
    timeout_s: float = 600.0,
    viewer: bool = True,
) -> Rehearsed:
    """One simulated participant through the session of `token`, until its advice is
    over, it leaves early, or the session ends. `speed` > 1 divides the waits (a quick
    rehearsal); the decision time sent is the drawn one. `viewer`: keep the 3-D view's
    websocket open meanwhile, as the page does (a task with a live 3-D view)."""
    task = get_task(model.task)
    if model.task == "sorting":
        advisor = FittedAdvisor(model, sort_rule, seed)
    else:
        advisor = FittedAdvisor(model, seed=seed, task=task)
    view = _Viewer(base_url, token) if viewer and task.live_view else None
    headers = {"Authorization": f"Bearer {token}"}
    times: list[float] = []
    with httpx.Client(base_url=base_url, headers=headers, timeout=60) as client:
        shown = _ok(client.get("/api/participant/consent"))
        _ok(client.post("/api/participant/consent", json={"agree": True,
                        "texts_version": shown["texts_version"]}))  # fmt: skip
        _pass_check(client, task)
        state = _ok(client.post("/api/participant/start"))
        if view is not None:
            view.start()
        stop_after = advisor.stop_after(int(state["advice_budget"]))
        deadline = time.monotonic() + timeout_s
        while state["status"] not in ENDED and time.monotonic() < deadline:
            if stop_after is not None and len(times) >= stop_after:
                break  # this person leaves: the session's idle limit will abandon it
            if state["advice_wanted"] and state["advice_index"] is not None:
                seen = _info(state) if task.live_view else None
                stage = stage_of(state["stage"]) if state.get("stage") else TRAINING
                action = advisor.advise_in(seen, stage)
                assert isinstance(action, int), "made without a budget: it never leaves itself"
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
    if view is not None:
        view.close()
    return Rehearsed(
        token_tail=token[-4:],
        advice=len(times),
        decision_times_s=times,
        left_early=stop_after is not None and len(times) >= stop_after,
        status=str(state["status"]),
        viewer_messages=view.messages if view is not None else 0,
        viewer_bytes=view.bytes if view is not None else 0,
    )


def _pass_check(client: httpx.Client, task: Task) -> None:
    """The study's comprehension check, passed as its people did (they had to, to advise):
    the task's own questions (a study's default check) answered right."""
    check = _ok(client.get("/api/participant/check"))
    if not check["required"] or check["passed"]:
        return
    right = {q.id: q.answer for q in task_questions(task)}
    unknown = [q["id"] for q in check["questions"] if q["id"] not in right]
    if unknown:
        raise RuntimeError(
            f"the study's own check question {unknown[0]!r}: a rehearsal answers only the "
            f"questions of task {task.name} (a design's default check)"
        )
    answers = {q["id"]: right[q["id"]] for q in check["questions"]}
    graded = _ok(client.post("/api/participant/check", json={"answers": answers}))
    assert graded["passed"], "the task's own answers pass its check"


def _ok(response: httpx.Response) -> dict[str, Any]:
    if response.status_code != 200:
        raise RuntimeError(
            f"{response.request.method} {response.request.url.path}: "
            f"{response.status_code} {response.text[:300]}"
        )
    data: dict[str, Any] = response.json()
    return data
