"""Participants an hour trained on a Ray cluster of two 1-CPU nodes on this machine,
against the server's two local trainer slots (issue 46).

    DATABASE_URL=postgresql://ideeprl:ideeprl@127.0.0.1/postgres \\
        python -m benchmarks.bench_ray_training --episodes 3

The same learner as `benchmarks.bench_training_queue` (the paper's, one torch thread,
fast motion, autonomous: what a slot trains once the advice is over), two sessions at a
time each way, in one PostgreSQL database (a cluster needs one): locally, two worker
processes (the batch's local backend, `run_session` as a slot's worker runs it); on the
cluster, `server.live.cluster.TrainingCluster` with one Ray task a session. Training
agent-steps a second while both trained (`busy_rate`), extrapolated to the paper's
`PAPER_TRAINING_STEPS` a participant. The cluster's nodes share this machine's cores,
so the number says what Ray and the database channel cost; on real machines each node
adds its own cores' rate (a prediction from the per-node rate, not a measurement).

Only a quiet machine gives that number. On a shared one, Linux's autogroups (on where
`/proc/sys/kernel/sched_autogroup_enabled` is 1) share the CPU between sessions: each Ray
node is a session of its own, while the two local workers share this one's, so under
load the cluster's processes get a larger share of the cores, and its rate looks higher.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path

from benchmarks.bench_population_batch import Log, busy_rate, fresh_study, load, template
from benchmarks.bench_training_queue import LOGS, PAPER_TRAINING_STEPS
from learner import machine
from runs.batch.backends import LocalBackend
from runs.worker.cluster import Handed
from runs.worker.worker import WorkerOptions
from server.live.cluster import TrainingCluster
from server.live.hub import Hub
from study.db.engine import make_engine, make_session_factory
from study.services.sessions import claim, create_session
from tests.server.live import fresh_database

SLOTS = 2


def sessions(url: str, study_id: int, args: argparse.Namespace) -> list[int]:
    factory = make_session_factory(make_engine(url))
    with factory() as db:
        run = template(args)
        return [create_session(db, study_id, run.replace(seed=i)).id for i in range(SLOTS)]


def local(url: str, study_id: int, args: argparse.Namespace, options: WorkerOptions) -> float:
    ids = sessions(url, study_id, args)
    backend = LocalBackend(url, options, SLOTS)
    for session_id in ids:
        backend.start((session_id,))
    left = set(ids)
    while left:
        time.sleep(0.5)
        ended = backend.ended()
        assert not any(ended.values()), ended
        left -= set(ended)
    backend.close()
    return rate(url, ids)


def rate(url: str, ids: list[int]) -> float:
    steps, seconds = busy_rate(url, ids)
    assert seconds > 0, "the two sessions never trained at once: give them more episodes"
    return steps / seconds


def cluster(url: str, study_id: int, args: argparse.Namespace, options: WorkerOptions) -> float:
    from ray.cluster_utils import Cluster

    nodes = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    nodes.add_node(num_cpus=1)
    nodes.wait_for_nodes()
    factory = make_session_factory(make_engine(url))
    trainer = TrainingCluster(nodes.address, factory, url, options, Hub())
    try:
        trainer.open()
        for session_id in sessions(url, study_id, args):
            with factory() as db:
                trainer.submit([Handed(session_id, claim(db, session_id, resume=False))])
        ids = trainer.running()
        assert trainer.wait(3600)
    finally:
        trainer.close()
        nodes.shutdown()
    return rate(url, ids)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_ray_training")
    parser.add_argument("--episodes", type=int, default=3, help="training episodes per run")
    parser.add_argument("--pretraining-steps", type=int, default=200)
    parser.add_argument("--checkpoint-every", type=int, default=10)
    parser.add_argument("--tiny", action="store_true", help="a tiny scale: checks it runs")
    parser.add_argument(
        "--cluster-first", action="store_true", help="measure the cluster first (order effects)"
    )
    stamp = datetime.now(UTC).strftime("%Y-%m-%dT%H%M%SZ")
    parser.add_argument("--log", type=Path, default=LOGS / f"ray-training-{stamp}.log")
    args = parser.parse_args(argv)
    load_before = os.getloadavg()[0]
    log = Log(args.log)
    given = sys.argv[1:] if argv is None else argv
    log(f"bench_ray_training {' '.join(given)} at {stamp}")
    log(f"{machine.cpu_kind()}; {load()}")
    if args.tiny:
        log("--tiny: a check that the script runs, not a measurement")
    with tempfile.TemporaryDirectory() as tmp, fresh_database(Path(tmp)) as url:
        study_id = fresh_study(url, "bench")
        options = WorkerOptions(data_dir=Path(tmp), checkpoint_every_episodes=args.checkpoint_every)
        rates = {}
        ways = [("two local slots", local), ("two 1-CPU Ray nodes", cluster)]
        for name, measure in reversed(ways) if args.cluster_first else ways:
            rates[name] = measure(url, study_id, args, options)
            per_hour = rates[name] * 3600 / PAPER_TRAINING_STEPS
            log(
                f"{name}: {rates[name]:.1f} training agent-steps/s while both trained, "
                f"{per_hour:.1f} participants/hour at paper scale; {load()}"
            )
    here, there = rates["two local slots"], rates["two 1-CPU Ray nodes"]
    log(f"the cluster's rate: {there / here:.2f}x the local slots' on this machine")
    log(
        f"prediction (not measured): a cluster of n nodes of c cores each trains about "
        f"n x c x {there / SLOTS * 3600 / PAPER_TRAINING_STEPS:.1f} participants/hour "
        "(this machine's per-CPU rate on the cluster), while the database keeps up"
    )
    if load_before > 1.0:
        log(
            f"the machine was shared (1-minute load {load_before:.2f} before it began): each "
            "way's processes got part of the cores, and the two ways' rates are as far apart as "
            "the load changed between them"
        )
    log(f"\nlog: {args.log}")


if __name__ == "__main__":
    main()
