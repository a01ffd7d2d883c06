"""`ideeprl power --study ID|NAME`: how many participants per arm a study needs, from its
pilot's sessions (`study.services.power`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from cli.commands.batch import add_database_options, settings_from
from cli.commands.common import (
    EXIT_USAGE,
    add_json_option,
    existing_database,
    find_study,
    print_json,
    service_exit_code,
    show_progress,
)

DESCRIPTION = """\
Plan a study from its pilot: for each method against the baseline, the observed effect on
R_T (the agents' total collected reward), the sd of R_T per arm, and how many agents
(participants) per arm the report's per-agent Welch test (two-sided) needs for 80 % and
90 % power. By simulation (studies drawn from the observed R_T, and from a normal fit,
seeded) and by the closed form of the normal approximation. Planning information, not a
test: with few pilot agents the effect and spreads are rough estimates.

Sessions are those the report covers: the study's finished sessions, except the agent
trained as an advisor, grouped by method. Each arm needs at least 2 agents."""


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "power",
        help="agents per arm a study needs for 80/90 %% power, from its pilot's sessions",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--study", required=True, help="study id or name")
    parser.add_argument(
        "--baseline",
        default="auto",
        help="method each other is compared with (default auto: autonomous)",
    )
    parser.add_argument("--alpha", type=float, default=0.05, help="significance level (0.05)")
    parser.add_argument(
        "--draws", type=int, help="simulated studies per number of agents (default 2000)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the simulations (0)")
    parser.add_argument(
        "--max-n", type=int, help="largest number of agents per arm searched (default 1000)"
    )
    parser.add_argument(
        "--n",
        type=int,
        nargs="+",
        default=[],
        metavar="N",
        help="also give the power at these numbers of agents per arm",
    )
    parser.add_argument(
        "--sessions", nargs="+", metavar="ID", help="these sessions only (any status)"
    )
    parser.add_argument("--methods", nargs="+", metavar="METHOD", help="these methods only")
    parser.add_argument("--label", help="sessions with this label only (a batch's name)")
    parser.add_argument(
        "--n-episodes", type=int, help="first N episodes of every agent (runs of unequal length)"
    )
    parser.add_argument(
        "--out", type=Path, help="folder to write power.png (with .svg and .pdf) and power.csv into"
    )
    add_json_option(parser, "the effects, spreads, agents needed and power curves")
    add_database_options(parser)
    parser.set_defaults(func=power)


def _needed(n: int | None, max_n: int) -> str:
    return f"> {max_n}" if n is None else str(n)


def power(args: argparse.Namespace) -> int:
    from analysis.episodes import method_name
    from cli.commands.report import _ints
    from study.db.engine import make_session_factory
    from study.services.errors import ServiceError
    from study.services.power import PowerRequest, study_power

    try:
        sessions = _ints(args.sessions) if args.sessions else None
    except argparse.ArgumentTypeError as error:
        print(f"error: {error}", file=sys.stderr)
        return EXIT_USAGE
    given = {"draws": args.draws, "max_n": args.max_n}  # absent: the library's defaults
    request = PowerRequest(
        sessions=sessions,
        baseline=args.baseline,
        alpha=args.alpha,
        seed=args.seed,
        methods=tuple(m for value in args.methods or [] for m in value.split(",") if m) or None,
        label=args.label,
        n_episodes=args.n_episodes,
        at_n=tuple(args.n),
        **{k: v for k, v in given.items() if v is not None},
    )
    tell = show_progress(False)

    def progress(line: str) -> None:
        if tell:
            print(f"simulating {line}...", file=sys.stderr, flush=True)

    engine = existing_database(settings_from(args))
    with make_session_factory(engine)() as db:
        study_id, _ = find_study(db, args.study)
        try:
            done = study_power(db, study_id, request, args.out, progress)
        except ServiceError as error:
            print(f"error: {error.message}", file=sys.stderr)
            return service_exit_code(error)
    result = done.analysis
    if args.json:
        print_json(
            {
                "study_id": study_id,
                "sessions": list(done.sessions),
                "n_episodes": done.n_episodes,
                "notes": list(done.notes),
                **result.to_dict(),
                "files": [str(p.resolve()) for p in done.files],
            }
        )
        return 0
    for note in done.notes:
        print(f"note: {note}")
    print(
        f"Power of Welch's two-sided t-test on agents' R_T ({done.n_episodes} episodes each) "
        f"at alpha {result.alpha:g}; {result.draws} simulated studies per size, seed "
        f"{result.seed}. Planning information, not a test."
    )
    for c in result.comparisons:
        print(
            f"\n{method_name(c.method)} vs {method_name(c.baseline)}: effect {c.delta:+.2f} "
            f"R_T (d = {c.d:.2f}); sd {c.sd:.2f} / {c.baseline_sd:.2f}; "
            f"pilot {c.agents} + {c.baseline_agents} agents"
        )
        print(f"  {'power':<7}{'bootstrap':>11}{'normal fit':>12}{'closed form':>13}  agents/arm")
        for s in c.sample_sizes:
            sizes = [_needed(n, result.max_n) for n in (s.bootstrap, s.fitted, s.closed_form)]
            print(f"  {f'{s.target:.0%}':<7}{sizes[0]:>11}{sizes[1]:>12}{sizes[2]:>13}")
        at = c.at_sizes
        for i, n in enumerate(at.n):
            print(
                f"  power with {n} agents per arm: {at.bootstrap[i]:.0%} (bootstrap), "
                f"{at.fitted[i]:.0%} (normal fit), {at.closed_form[i]:.0%} (closed form)"
            )
    for skipped in result.skipped:
        print(f"\nleft out: {skipped}")
    if done.files:
        print(f"\nfiles: {', '.join(str(p) for p in done.files)}")
    return 0
