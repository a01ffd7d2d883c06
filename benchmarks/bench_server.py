"""The advice round trip under load: 8 simulated participants advise at once while 2
machine sessions train, against a real server on loopback.

Round trip = submit an action (POST /api/participant/advice) until the next observation
arrives (long-poll GET /api/participant/state). It includes the worker's environment
step. Printed with a bare request (GET /api/health) measured at the same time, as the
reference for what this loaded machine gives any request. Aim: p95 < 150 ms.

    python -m benchmarks.bench_server [--participants 8] [--trainers 2] [--advice 40]
"""

from __future__ import annotations

import argparse
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
    while any(api.get(f"/api/sessions/{i}/progress").json()["phase"] != "training" for i in ids):
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
                    body = {"method": "oracle", "seed": seed, "config": CONFIG, "episodes": 300}
                    trainer_ids.append(api.post(make, json=body).json()["id"])
                    api.post(f"/api/sessions/{trainer_ids[-1]}/start")
                wait_training(api, trainer_ids)
                tokens = []
                for seed in range(participants):
                    body = {
                        "method": "human",
                        "seed": seed,
                        "motion": motion,
                        "advice_budget": advice + 1,
                        "config": {**CONFIG, "pretraining_steps": advice + 20},
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
        + ", ".join(f"{p['phase']} step {p['global_step']}" for p in progress)
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--participants", type=int, default=8)
    parser.add_argument("--trainers", type=int, default=2)
    parser.add_argument("--advice", type=int, default=40, help="advice per participant")
    parser.add_argument("--motion", choices=["fast", "physics"], default="fast")
    args = parser.parse_args([] if __name__ != "__main__" else None)
    run(args.participants, args.trainers, args.advice, args.motion)


if __name__ == "__main__":
    main()
