"""`ideeprl batch`: the autonomous and machine-advised baselines (and Stable-Baselines3's DQN),
N agents per method, as sessions of a study; run it again to finish an interrupted batch."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from server.commands.common import service_exit_code, show_progress

if TYPE_CHECKING:  # the command line starts without the batch's imports
    from sqlalchemy.orm import Session

    from server.batch import BatchResult, BatchSpec, RunnerOptions
    from server.settings import Settings

DESCRIPTION = """\
Run N agents per method (autonomous, agent, oracle, random, sb3-dqn) as sessions of a
study, in parallel worker processes on this machine or on Ray. Agent i of every method gets
seed BASE+i, so runs pair up across methods. The 'agent' method needs a trained advisor:
without --advisor-checkpoint the batch first trains one (autonomous, same settings, seed
BASE+100000) and stores it as a session too. 'sb3-dqn' is Stable-Baselines3's DQN, unadvised,
on the same scenario, seeds and scale, its hyperparameters mapped from the paper's (the
optional extra: pip install 'ideeprl[sb3]'); the report flags it as another learner.

Runs are identified by study, method, seed and configuration: the same command again skips
finished runs, resumes interrupted ones from their checkpoints and creates only the missing
ones. Ctrl-C stops the running runs at a checkpoint.

Reduced scale for demos and CI: --episodes 5 --pretraining-steps 200 --advice-budget 20
--set batch_size=32 --set memory_size=2000."""


def _methods(values: list[str]) -> tuple[str, ...]:
    return tuple(m for value in values for m in value.split(",") if m)


def _override(text: str) -> tuple[str, Any]:
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"expected FIELD=VALUE, got {text!r}")
    name, value = text.split("=", 1)
    try:
        return name.strip(), json.loads(value)
    except json.JSONDecodeError:
        return name.strip(), value


def add_database_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--data-dir", type=Path, help="data folder (default: IDEEPRL_DATA_DIR or study_data)"
    )
    parser.add_argument(
        "--database-url", help="SQLAlchemy URL (default: DATABASE_URL, else the data folder's)"
    )


def settings_from(args: argparse.Namespace) -> Settings:
    from server.settings import Settings

    overrides = {"data_dir": args.data_dir, "database_url": args.database_url}
    return Settings(**{k: v for k, v in overrides.items() if v is not None})


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "batch",
        help="run baseline agents (autonomous, agent, oracle, random, sb3-dqn) as a study's "
        "sessions",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    what = parser.add_argument_group("what to run")
    what.add_argument(
        "--study",
        required=True,
        help="study id, or a name (the study of that name, created if missing)",
    )
    what.add_argument(
        "--methods",
        nargs="+",
        default=["autonomous,agent"],
        metavar="METHOD",
        help="autonomous, agent, oracle, random, sb3-dqn (space or comma separated; "
        "default autonomous agent)",
    )
    what.add_argument("--agents", type=int, default=10, help="agents per method (default 10)")
    what.add_argument("--seed", type=int, default=0, help="base seed (default 0)")
    what.add_argument(
        "--label", default="baselines", help="the batch's name, every run's session label"
    )
    what.add_argument("--preset", default="paper", help="learner preset: paper, modern or authors")
    what.add_argument("--episodes", type=int, help="training episodes per run (default 300)")
    what.add_argument("--pretraining-steps", type=int, help="pretraining actions (default 1000)")
    what.add_argument("--advice-budget", type=int, help="advice per advised run (default 100)")
    what.add_argument("--max-episode-steps", type=int, help="truncation (default 250)")
    what.add_argument(
        "--set",
        dest="overrides",
        action="append",
        type=_override,
        default=[],
        metavar="FIELD=VALUE",
        help="learner config field (VALUE as JSON), repeatable",
    )
    what.add_argument("--strategy", default="early", help="advising strategy (default early)")
    what.add_argument("--interval", type=int, help="alternating: advise every Nth step (2)")
    what.add_argument(
        "--threshold", type=float, help="importance, mistake_correcting: Q-value spread (0.1)"
    )
    what.add_argument(
        "--oracle-error-rate", type=float, default=0.0, help="oracle's wrong-advice rate"
    )
    what.add_argument("--advisor-checkpoint", help="trained checkpoint advising 'agent' runs")
    what.add_argument("--motion", default="fast", help="fast (default) or physics")
    what.add_argument(
        "--sort-rule", default="color", help='color, shape, or a JSON map {"cube/red": "left"}'
    )
    what.add_argument(
        "--reward-scheme",
        nargs="+",
        default=["paper"],
        metavar="[METHOD=]SCHEME",
        help="paper (default), authors-autonomous or authors-interactive, for every method, "
        "or METHOD=SCHEME for one (how the authors compared: autonomous=authors-autonomous "
        "agent=authors-interactive; the report flags it)",
    )
    what.add_argument(
        "--grasp-failure-rate", type=float, default=0.0, help="chance a grab comes back empty"
    )
    what.add_argument(
        "--knock-off-rate", type=float, default=0.0, help="chance a grab knocks another off"
    )
    how = parser.add_argument_group("how to run it")
    how.add_argument("--backend", choices=("local", "ray"), default="local")
    how.add_argument("--address", help="Ray cluster address (default: start a local Ray)")
    how.add_argument(
        "--workers", type=int, help="runs at once (default: cores / threads; Ray: its CPUs)"
    )
    how.add_argument("--threads", type=int, default=1, help="torch threads per run (default 1)")
    how.add_argument(
        "--checkpoint-every", type=int, default=10, help="episodes between checkpoints"
    )
    how.add_argument("--nice", type=int, default=0, help="workers' added niceness (0-19)")
    how.add_argument("--report", type=Path, metavar="DIR", help="write the report here at the end")
    how.add_argument("--dry-run", action="store_true", help="show the runs and their state only")
    how.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_database_options(how)
    parser.set_defaults(func=batch)


def spec_from(args: argparse.Namespace) -> BatchSpec:
    from server.batch import BatchSpec

    config = dict(args.overrides)
    if args.pretraining_steps is not None:
        config["pretraining_steps"] = args.pretraining_steps
    sort_rule: Any = args.sort_rule
    if sort_rule.strip().startswith("{"):
        sort_rule = json.loads(sort_rule)
    scenario: dict[str, Any] = {
        "grasp_failure_rate": args.grasp_failure_rate,
        "knock_off_rate": args.knock_off_rate,
    }
    per_method: dict[str, str] = {}
    for item in args.reward_scheme:
        method, sep, scheme = item.rpartition("=")
        if sep:
            per_method[method] = scheme
        else:
            scenario["reward_scheme"] = scheme
    return BatchSpec(
        methods=_methods(args.methods),
        agents=args.agents,
        base_seed=args.seed,
        label=args.label,
        preset=args.preset,
        config=config,
        episodes=args.episodes,
        max_episode_steps=args.max_episode_steps,
        advice_budget=args.advice_budget,
        strategy=args.strategy,
        strategy_options={
            name: value
            for name, value in (("interval", args.interval), ("threshold", args.threshold))
            if value is not None
        },
        oracle_error_rate=args.oracle_error_rate,
        advisor_checkpoint=args.advisor_checkpoint,
        motion=args.motion,
        sort_rule=sort_rule,
        scenario=scenario,
        reward_schemes=per_method,
    )


def command_line(args: argparse.Namespace, spec: BatchSpec) -> str:
    """The command that reruns (or resumes) exactly this batch, every choice spelled out."""
    parts = ["ideeprl", "batch", "--study", str(args.study), "--methods", *spec.methods]
    parts += ["--agents", str(spec.agents), "--seed", str(spec.base_seed), "--label", spec.label]
    parts += ["--preset", spec.preset]
    for flag, value in (
        ("--episodes", spec.episodes),
        ("--pretraining-steps", args.pretraining_steps),
        ("--advice-budget", spec.advice_budget),
        ("--max-episode-steps", spec.max_episode_steps),
        ("--advisor-checkpoint", spec.advisor_checkpoint),
    ):
        if value is not None:
            parts += [flag, str(value)]
    for name, value in args.overrides:
        parts += ["--set", f"{name}={json.dumps(value)}"]
    if "oracle" in spec.methods:
        parts += ["--oracle-error-rate", str(spec.oracle_error_rate)]
    parts += ["--strategy", spec.strategy]
    for name, value in spec.strategy_options.items():
        parts += [f"--{name}", str(value)]
    parts += ["--motion", spec.motion]
    if spec.sort_rule != "color":
        parts += ["--sort-rule", json.dumps(spec.sort_rule)]
    schemes = [spec.scenario.get("reward_scheme", "paper")]
    schemes += [f"{method}={scheme}" for method, scheme in spec.reward_schemes.items()]
    parts += ["--reward-scheme", *schemes]
    for name in ("grasp_failure_rate", "knock_off_rate"):
        if spec.scenario.get(name):
            parts += ["--" + name.replace("_", "-"), str(spec.scenario[name])]
    parts += ["--backend", args.backend]
    if args.address:
        parts += ["--address", args.address]
    if args.workers:
        parts += ["--workers", str(args.workers)]
    parts += ["--threads", str(args.threads), "--checkpoint-every", str(args.checkpoint_every)]
    if args.nice:
        parts += ["--nice", str(args.nice)]
    if args.data_dir:
        parts += ["--data-dir", str(args.data_dir)]
    if args.database_url:
        from sqlalchemy.engine import make_url

        parts += ["--database-url", make_url(args.database_url).render_as_string()]
    if args.report:
        parts += ["--report", str(args.report)]
    return shlex.join(parts)


def resolve_study(db: Session, study: str) -> tuple[int, str]:
    """The study named by id or name; a new name creates the study. Returns (id, what)."""
    from sqlalchemy import select

    from server.db.models import Study
    from server.schemas.studies import StudyCreate
    from server.services.studies import create_study

    if study.isdigit():
        found = db.get(Study, int(study))
        if found is None:
            names = [f"{s.id} ({s.name})" for s in db.scalars(select(Study).order_by(Study.id))]
            known = f"; studies: {', '.join(names)}" if names else "; there are no studies yet"
            raise LookupError(
                f"no study with id {study}{known}. Give a name instead to create a study"
            )
        return found.id, f"study {found.id} ({found.name})"
    found = db.scalar(select(Study).where(Study.name == study))
    if found is not None:
        return found.id, f"study {found.id} ({found.name})"
    created = create_study(db, StudyCreate(name=study, description="Baselines run in batch."))
    return created.id, f"new study {created.id} ({created.name})"


def _fail(message: str, code: int = 2) -> int:
    """Exit 2 for options that make no sense, 1 (`code=1`) for what went wrong running."""
    print(f"error: {message}", file=sys.stderr)
    return code


def batch(args: argparse.Namespace) -> int:
    from pydantic import ValidationError

    from server.batch import BatchError
    from server.db.engine import make_engine, make_session_factory
    from server.db.migrate import upgrade
    from server.services.errors import ServiceError

    try:
        spec = spec_from(args)
        _check_counts(args)
    except (BatchError, json.JSONDecodeError) as error:
        return _fail(str(error))
    settings = settings_from(args)
    engine = make_engine(settings.db_url)
    upgrade(engine)
    try:
        with make_session_factory(engine)() as db:
            study_id, what = resolve_study(db, args.study)
        print(f"{what}, database {settings.db_url}")
        if args.dry_run:
            from server.batch.runner import BatchRunner

            runner = BatchRunner(spec, study_id, settings.db_url, _options(args, settings))
            print("\n".join(runner.preview()))
            return 0
        return _run(args, spec, study_id, settings)
    except LookupError as error:
        return _fail(str(error), 1)
    except ServiceError as error:
        return _fail(error.message, service_exit_code(error))
    except (BatchError, ValidationError) as error:
        return _fail(str(error))


def _check_counts(args: argparse.Namespace) -> None:
    from server.batch import BatchError

    for flag, value, low in (
        ("--workers", args.workers, 1),
        ("--threads", args.threads, 1),
        ("--checkpoint-every", args.checkpoint_every, 1),
        ("--episodes", args.episodes, 1),
        ("--pretraining-steps", args.pretraining_steps, 0),
        ("--advice-budget", args.advice_budget, 0),
        ("--max-episode-steps", args.max_episode_steps, 1),
    ):
        if value is not None and value < low:
            raise BatchError(f"{flag} must be at least {low}, got {value}")
    if not 0 <= args.nice <= 19:
        raise BatchError(f"--nice must be between 0 and 19, got {args.nice}")
    if args.address and args.backend != "ray":
        raise BatchError("--address is for the Ray backend: add --backend ray")


def _options(args: argparse.Namespace, settings: Settings) -> RunnerOptions:
    from server.batch import RunnerOptions

    return RunnerOptions(
        data_dir=settings.data_dir,
        backend=args.backend,
        workers=args.workers,
        threads=args.threads,
        address=args.address,
        checkpoint_every_episodes=args.checkpoint_every,
        heartbeat_s=settings.heartbeat_s,
        stale_after_s=settings.stale_after_s,
        nice=args.nice,
        progress=show_progress(args.no_progress),
    )


def _run(args: argparse.Namespace, spec: BatchSpec, study_id: int, settings: Settings) -> int:
    from server.batch import describe
    from server.batch.runner import BatchRunner

    result = BatchRunner(spec, study_id, settings.db_url, _options(args, settings)).run()
    print("\n".join(describe(result)))
    if result.interrupted or not result.complete:
        print(f"to finish the batch, run the same command again:\n  {command_line(args, spec)}")
        return 130 if result.interrupted else 1
    print(f"all {len(result.runs)} runs finished in study {study_id} ({result.wall_time_s:.0f} s)")
    if args.report:
        return _report(args, spec, result, settings)
    print(f"report: ideeprl report --study {study_id} --label {shlex.quote(spec.label)} --out DIR")
    return 0


def _report(
    args: argparse.Namespace, spec: BatchSpec, result: BatchResult, settings: Settings
) -> int:
    from server.batch.provenance import describe_times, environment, training_times
    from server.db.engine import make_engine, make_session_factory
    from server.services.reports import ReportRequest, build_report

    factory = make_session_factory(make_engine(settings.db_url))
    with factory() as db:
        times = training_times(db, result.session_ids(include_advisor=True))
        advisor = result.advisor
        notes = [
            f"Command: `{command_line(args, spec)}`",
            *environment(),
            f"Wall time of the batch command that finished it: "
            f"{result.wall_time_s / 3600:.2f} h; training time: {describe_times(times)}.",
        ]
        if advisor is not None:
            notes.append(
                f"Advisor of the agent-IDeepRL runs: session {advisor.session_id} (autonomous, "
                f"seed {advisor.run.seed}, same settings), trained first."
            )
        built = build_report(
            db,
            result.study_id,
            args.report,
            ReportRequest(sessions=tuple(result.session_ids()), notes=tuple(notes)),
        )
    print(f"report: {built.result.report}")
    return 0
