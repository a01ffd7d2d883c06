"""The study server under load, against a real server on loopback; three scenarios.

`advice`: 8 simulated participants advise at once while 2 machine sessions train. Round
trip = submit an action (POST /api/participant/advice) until the next observation arrives
(long-poll GET /api/participant/state). It includes the worker's environment step. Printed
with a bare request (GET /api/health) measured at the same time, as the reference for what
this loaded machine gives any request. Aim: p95 < 150 ms.

`first-turn`: a human session at default settings (1,000 pretraining steps, 100 advice,
physics motion). The participant opens the link (which starts the random pretraining),
consents, reads the induction for R seconds, presses Start: the time from Start to the
first advice request. Aim: under 5 s. Also the time from opening the link to the robot
being ready, which says how long a reading makes the wait vanish.

`study`: 11 human sessions, each advising its budget (10 to 40 advice, staggered) and then
training, queued for the server's trainer slots (one per core): the advice round trips of
the sessions still advising while the others train. Aim: p95 < 100 ms.

    python -m benchmarks.bench_server [--scenario advice|first-turn|study|all] [--runs 3]
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import statistics
import tempfile
import threading
import time
from pathlib import Path

import httpx

from tests.server.live import LiveServer
from tests.server.participant import SimulatedParticipant

CONFIG = {"pretraining_steps": 200, "batch_size": 32, "memory_size": 5000}


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q / 100 * (len(ordered) - 1)))]


def advise_loop(
    participant: SimulatedParticipant, count: int, out: list[float], ready: threading.Barrier
) -> None:
    participant.begin()
    state = participant.next_request()
    ready.wait()  # all workers started: measure advising, not process start-up
    for _ in range(count):
        index = state["advice_index"]
        started = time.perf_counter()
        assert participant.advise(index, index % 4, wait=20).status_code == 200
        state = participant.next_request()
        if not state["advice_wanted"]:
            break
        assert state["advice_index"] == index + 1
        out.append(time.perf_counter() - started)


def wait_training(api: httpx.Client, ids: list[int]) -> None:
    """Measure only once the machine sessions are past pretraining, training for real."""
    deadline = time.monotonic() + 300
    while any(api.get(f"/api/sessions/{i}/progress").json()["stage"] != "train" for i in ids):
        assert time.monotonic() < deadline, "the training sessions did not reach training"
        time.sleep(0.5)


def bare_loop(url: str, stop: threading.Event, out: list[float]) -> None:
    with httpx.Client(base_url=url) as client:
        while not stop.is_set():
            started = time.perf_counter()
            client.get("/api/health")
            out.append(time.perf_counter() - started)
            time.sleep(0.05)


def run(participants: int, trainers: int, advice: int, motion: str) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        server = LiveServer(Path(tmp), f"sqlite:///{tmp}/bench.sqlite3").start()
        try:
            with server.client() as api:
                study = api.post("/api/studies", json={"name": "bench"}).json()["id"]
                make = f"/api/studies/{study}/sessions"
                trainer_ids = []
                for seed in range(trainers):
                    run = {"method": "oracle", "seed": seed, "config": {**CONFIG, "episodes": 300}}
                    body = {"run": run}
                    trainer_ids.append(api.post(make, json=body).json()["id"])
                    api.post(f"/api/sessions/{trainer_ids[-1]}/start")
                wait_training(api, trainer_ids)
                tokens = []
                for seed in range(participants):
                    config = {
                        **CONFIG,
                        "pretraining_steps": advice + 20,
                        "advice_budget": advice + 1,
                    }
                    body = {
                        "run": {"method": "human", "seed": seed, "motion": motion, "config": config}
                    }
                    tokens.append(api.post(make, json=body).json()["participant_token"])
                round_trips: list[float] = []
                bare: list[float] = []
                stop = threading.Event()
                ready = threading.Barrier(len(tokens))
                threads = [
                    threading.Thread(
                        target=advise_loop,
                        args=(SimulatedParticipant(server.url, t), advice, round_trips, ready),
                    )
                    for t in tokens
                ]
                reference = threading.Thread(target=bare_loop, args=(server.url, stop, bare))
                reference.start()
                started = time.perf_counter()
                for thread in threads:
                    thread.start()
                for thread in threads:
                    thread.join()
                wall = time.perf_counter() - started
                stop.set()
                reference.join()
                progress = [
                    api.get(f"/api/sessions/{s['id']}/progress").json()
                    for s in api.get(make).json()
                    if s["method"] == "oracle"
                ]
        finally:
            server.stop()
    ms = 1000
    print(
        f"{participants} participants ({motion} motion) advising while {trainers} sessions "
        f"train; {len(round_trips)} advice in {wall:.1f} s"
    )
    print(f"{'':28}{'n':>6}{'p50 ms':>10}{'p95 ms':>10}{'mean ms':>10}")
    for name, values in (("advice round trip", round_trips), ("bare GET /api/health", bare)):
        print(
            f"{name:28}{len(values):>6}{percentile(values, 50) * ms:>10.1f}"
            f"{percentile(values, 95) * ms:>10.1f}{statistics.fmean(values) * ms:>10.1f}"
        )
    print(f"round trip p50 / bare p50: {percentile(round_trips, 50) / percentile(bare, 50):.1f}x")
    print(
        "trainers meanwhile reached: "
        + ", ".join(f"{p['stage']} step {p['global_step']}" for p in progress)
    )


def first_turn(reading_s: list[float], runs: int) -> None:
    """End of the induction to the first turn, at default settings."""
    results: dict[float, list[tuple[float, float]]] = {r: [] for r in reading_s}
    with tempfile.TemporaryDirectory() as tmp:
        server = LiveServer(Path(tmp), f"sqlite:///{tmp}/bench.sqlite3").start()
        try:
            with server.client() as api:
                study = api.post("/api/studies", json={"name": "first turn"}).json()["id"]
                for _ in range(runs):
                    for reading in reading_s:
                        body = {"run": {"method": "human"}}  # the paper's defaults, physics motion
                        made = api.post(f"/api/studies/{study}/sessions", json=body).json()
                        results[reading].append(_one_first_turn(server, made, reading))
                        api.post(f"/api/sessions/{made['id']}/stop")
        finally:
            server.stop()
    print(f"first turn at default settings, {runs} runs each (median, min-max)")
    print(f"{'reading the induction':24}{'link -> robot ready s':>24}{'Start -> first turn s':>24}")
    for reading, values in results.items():
        ready = [v[0] for v in values if not math.isnan(v[0])]
        wait = [v[1] for v in values]
        print(f"{f'{reading:.0f} s':24}{_spread(ready):>24}{_spread(wait):>24}")


def _spread(values: list[float]) -> str:
    if not values:
        return "(not seen)"
    return f"{statistics.median(values):.1f} ({min(values):.1f}-{max(values):.1f})"


def _one_first_turn(server: LiveServer, session: dict, reading_s: float) -> tuple[float, float]:
    """(link opened -> robot ready, Start -> first advice request), in seconds; the first
    is NaN when the reading ended before the robot was ready."""
    participant = SimulatedParticipant(server.url, session["participant_token"])
    opened = time.perf_counter()
    participant.client.get(f"/p/{session['participant_token']}", follow_redirects=False)
    participant.consent()
    ready_after = math.nan
    while True:
        readiness = participant.client.get("/api/participant/readiness").json()
        if math.isnan(ready_after) and readiness["ready"]:
            ready_after = time.perf_counter() - opened
        if time.perf_counter() - opened >= reading_s:
            break
        time.sleep(0.1)
    started = time.perf_counter()
    assert participant.client.post("/api/participant/start").status_code == 200
    state = participant.next_request(timeout=600)
    assert state["advice_wanted"], state
    turn = time.perf_counter() - started
    participant.close()
    return ready_after, turn


STUDY_SESSIONS = 11


def study(runs: int, motion: str = "physics", think_s: float = 0.0) -> None:
    """11 participants; each advises its budget, then its session trains in a queue."""
    client: list[list[float]] = []
    server: list[list[float]] = []
    peaks = []
    for _ in range(runs):
        trips, turnarounds, peak = _one_study(motion, think_s)
        client.append(trips)
        server.append(turnarounds)
        peaks.append(peak)
    print(
        f"{STUDY_SESSIONS} human sessions ({motion} motion), advising 10-40 advice each "
        f"({think_s:.1f} s to decide each), then training queued for "
        f"{len(os.sched_getaffinity(0))} trainer slots; {runs} runs"
    )
    for name, values in (
        ("server side: advice received -> next advice asked", server),
        ("participant's round trip: click -> next turn shown", client),
    ):
        p50s = [percentile(v, 50) * 1000 for v in values]
        p95s = [percentile(v, 95) * 1000 for v in values]
        print(f"  {name} ({[len(v) for v in values]} per run)")
        for q, per_run in (("p50", p50s), ("p95", p95s)):
            rounded = [round(v, 1) for v in per_run]
            print(f"    {q} ms per run: {rounded}; median {statistics.median(per_run):.1f}")
    print(
        "  most seen at once (training, queued, advising): "
        + ", ".join(f"({t}, {q}, {a})" for t, q, a in peaks)
    )


def _one_study(
    motion: str, think_s: float
) -> tuple[list[float], list[float], tuple[int, int, int]]:
    trips: list[float] = []
    peak = [0, 0, 0]
    with tempfile.TemporaryDirectory() as tmp:
        database = f"{tmp}/bench.sqlite3"
        server = LiveServer(Path(tmp), f"sqlite:///{database}").start()
        try:
            with server.client() as api:
                study_id = api.post("/api/studies", json={"name": "study"}).json()["id"]
                made = []
                for i in range(STUDY_SESSIONS):
                    budget = 10 + 3 * i
                    config = {
                        **CONFIG,
                        "pretraining_steps": budget + 40,
                        "advice_budget": budget,
                        "episodes": 300,
                    }
                    body = {
                        "run": {"method": "human", "seed": i, "motion": motion, "config": config}
                    }
                    response = api.post(f"/api/studies/{study_id}/sessions", json=body)
                    assert response.status_code == 201, response.text
                    made.append(response.json())
                ready = threading.Barrier(len(made) + 1)
                threads = [
                    threading.Thread(
                        target=_advise_budget,
                        args=(
                            server.url,
                            m["participant_token"],
                            m["run"]["config"]["advice_budget"],
                            trips,
                            ready,
                            think_s,
                        ),
                    )
                    for m in made
                ]
                for thread in threads:
                    thread.start()
                ready.wait(timeout=900)  # a participant that failed breaks it: no hang
                while any(t.is_alive() for t in threads):
                    rows = [api.get(f"/api/sessions/{m['id']}/progress").json() for m in made]
                    now = (
                        sum(r["stage"] == "train" and not r["queued"] for r in rows),
                        sum(r["queued"] for r in rows),
                        sum(r["advice_left"] > 0 for r in rows),
                    )
                    peak = [max(p, n) for p, n in zip(peak, now, strict=True)]
                    time.sleep(0.5)
                for thread in threads:
                    thread.join()
        finally:
            server.stop()
        turnarounds = _server_turnarounds(database)
    return trips, turnarounds, (peak[0], peak[1], peak[2])


def _server_turnarounds(database: str) -> list[float]:
    """From the server's own stamps: each advice's answer to the next advice's request, in
    the same session (the worker's step, the database, the message to the web process)."""
    import sqlite3
    from datetime import datetime

    with sqlite3.connect(database) as db:
        rows = db.execute(
            "select session_id, advice_index, requested_at, answered_at from advice "
            "order by session_id, advice_index"
        ).fetchall()
    out = []
    for before, after in itertools.pairwise(rows):
        if before[0] == after[0] and after[1] == before[1] + 1:
            asked = datetime.fromisoformat(after[2])
            answered = datetime.fromisoformat(before[3])
            out.append((asked - answered).total_seconds())
    return out


def _advise_budget(
    url: str,
    token: str,
    budget: int,
    out: list[float],
    ready: threading.Barrier,
    think_s: float = 0.0,
) -> None:
    """Advise every advice of the budget, `think_s` after each turn is shown, timing each
    round trip but the last (after it the session trains and no request follows)."""
    participant = SimulatedParticipant(url, token)
    participant.begin()
    state = participant.next_request(timeout=600)
    ready.wait()  # every worker started: measure advising, not process start-up
    for index in range(budget):
        assert state["advice_index"] == index, state
        time.sleep(think_s)
        if index == budget - 1:
            assert participant.advise(index, index % 4).status_code == 200
            break
        started = time.perf_counter()
        assert participant.advise(index, index % 4, wait=20).status_code == 200
        state = participant.next_request()
        out.append(time.perf_counter() - started)
    participant.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--scenario", choices=["advice", "first-turn", "study", "all"], default="all"
    )
    parser.add_argument("--runs", type=int, default=3, help="runs of first-turn and study")
    parser.add_argument("--participants", type=int, default=8)
    parser.add_argument("--trainers", type=int, default=2)
    parser.add_argument("--advice", type=int, default=40, help="advice per participant")
    parser.add_argument("--motion", choices=["fast", "physics"], default="fast")
    parser.add_argument(
        "--reading", type=float, nargs="+", default=[0.0, 20.0, 60.0], help="first-turn: seconds"
    )
    parser.add_argument("--study-motion", choices=["fast", "physics"], default="physics")
    parser.add_argument(
        "--think", type=float, default=0.0, help="study: seconds each participant takes to decide"
    )
    args = parser.parse_args([] if __name__ != "__main__" else None)
    if args.scenario in ("advice", "all"):
        run(args.participants, args.trainers, args.advice, args.motion)
    if args.scenario in ("first-turn", "all"):
        first_turn(args.reading, args.runs)
    if args.scenario in ("study", "all"):
        study(args.runs, args.study_motion, args.think)


if __name__ == "__main__":
    main()
