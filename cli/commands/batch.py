"""`ideeprl batch`: the autonomous and machine-advised baselines (and Stable-Baselines3's DQN),
N agents per method, as sessions of a study; run it again to finish an interrupted batch."""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cli.commands.common import (
    add_deprecated,
    add_set_option,
    existing_database,
    given_values,
    service_exit_code,
    show_progress,
    shown_url,
)
from learner.fields import FieldError, leaves, nest, parse_text
from learner.fields import add_arguments as add_spec_arguments
from learner.run import declared, run_flags

if TYPE_CHECKING:  # the command line starts without the batch's imports
    from sqlalchemy.orm import Session

    from runs.batch import BatchResult, BatchSpec, RunnerOptions
    from study.settings import Settings

DESCRIPTION = """\
Run N agents per method (autonomous, agent, oracle, random, procedure, sb3-dqn, fitted,
replayed) as
sessions of a study, in parallel worker processes on this machine or on Ray. Agent i of
every method gets seed BASE+i, so runs pair up across methods. The 'agent' method needs a
trained advisor: without --advisor-checkpoint the batch first trains one (autonomous, same
settings, seed BASE+100000) and stores it as a session too. 'sb3-dqn' is Stable-
Baselines3's DQN, unadvised, on the same scenario, seeds and scale, its hyperparameters
mapped from the paper's (the optional extra: pip install 'ideeprl[sb3]'); the report flags
it as another learner.

'replayed' re-runs every finished session of --replay-study (human ones by default,
--replay-methods) under this batch's run, fed its recorded advice by order: the same
people's advice, another learner (replayed run i gets seed BASE+i).

Runs are identified by study, method, seed and configuration: the same command again skips
finished runs, resumes interrupted ones from their checkpoints and creates only the missing
ones. Ctrl-C stops the running runs at a checkpoint.

Reduced scale for demos and CI: --episodes 5 --pretraining-steps 200 --advice-budget 20
--set batch_size=32 --set memory_size=2000."""


def _methods(values: list[str]) -> tuple[str, ...]:
    return tuple(m for value in values for m in value.split(",") if m)


def _per_method(text: str) -> tuple[str, str, str]:
    method, sep, rest = text.partition(":")
    name, eq, value = rest.partition("=")
    if not sep or not eq or not method.strip() or not name.strip():
        raise argparse.ArgumentTypeError("--per-method takes METHOD:FIELD=VALUE")
    return method.strip(), name.strip(), value


def add_database_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--data-dir", type=Path, help="data folder (default: IDEEPRL_DATA_DIR or study_data)"
    )
    parser.add_argument(
        "--database-url", help="SQLAlchemy URL (default: DATABASE_URL, else the data folder's)"
    )


def settings_from(args: argparse.Namespace) -> Settings:
    from study.settings import Settings

    overrides = {"data_dir": args.data_dir, "database_url": args.database_url}
    return Settings(**{k: v for k, v in overrides.items() if v is not None})


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "batch",
        help="run baseline agents (autonomous, agent, oracle, random, sb3-dqn, fitted) as a "
        "study's sessions",
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
        help="autonomous, agent, oracle, random, procedure, sb3-dqn, fitted, replayed (space or "
        "comma separated; default autonomous agent)",
    )
    what.add_argument("--agents", type=int, default=10, help="agents per method (default 10)")
    what.add_argument(
        "--replay-study",
        type=int,
        metavar="ID",
        help="with method replayed: the study whose completed sessions are re-run under this "
        "batch's run, each fed its recorded advice by order (the same people's advice, "
        "another learner); replayed run i gets seed BASE+i",
    )
    what.add_argument(
        "--replay-methods",
        default="human",
        metavar="METHODS",
        help="with --replay-study: the methods of the sessions to replay (comma separated; "
        "default human)",
    )
    what.add_argument(
        "--label", default="baselines", help="the batch's name, every run's session label"
    )
    what.add_argument(
        "--control-of",
        default="agent",
        metavar="METHOD",
        help="the advised method (agent, oracle, random) whose runs the 'procedure' method's "
        "runs follow: agent i's control asks at the same steps, fits as often and follows "
        "the same epsilon, with random actions in place of the advice (default agent)",
    )
    run = parser.add_argument_group(
        "the runs",
        "every field of learner.run.RunSpec, one flag each (or --set FIELD=VALUE), shared "
        "by every method's runs; --seed is the base seed (agent i gets seed + i)",
    )
    add_spec_arguments(
        run, declared(), skip=("method",), defaults={"torch_threads": "1 (half the cores, 1-4)"}
    )
    add_deprecated(parser, skip=("method",))
    add_set_option(what, "set any field of the runs by its name")
    what.add_argument(
        "--run",
        dest="run_file",
        type=Path,
        metavar="FILE",
        help="a run's JSON document (an exported session's run_spec, a session's `run` from "
        "the API) as the template; flags given beside it change its fields",
    )
    what.add_argument(
        "--per-method",
        action="append",
        type=_per_method,
        default=[],
        metavar="METHOD:FIELD=VALUE",
        help="set a field for one method's runs only, repeatable: how the authors compared "
        "(autonomous:reward_scheme=authors-autonomous agent:reward_scheme=authors-interactive; "
        "the report flags such a comparison)",
    )
    how = parser.add_argument_group("how to run it")
    how.add_argument("--backend", choices=("local", "ray"), default="local")
    how.add_argument("--address", help="Ray cluster address (default: start a local Ray)")
    how.add_argument(
        "--workers", type=int, help="runs at once (default: cores / torch threads; Ray: its CPUs)"
    )
    how.add_argument(
        "--checkpoint-every", type=int, default=10, help="episodes between checkpoints"
    )
    how.add_argument(
        "--population",
        type=int,
        metavar="N",
        help="runs that share one learner configuration train together, up to N per worker "
        "process (default: 2 on a CPU, 16 on CUDA, as the memory allows; 1: each run alone)",
    )
    how.add_argument("--nice", type=int, default=0, help="workers' added niceness (0-19)")
    how.add_argument(
        "--override-numerics",
        action="store_true",
        help="resume runs pinned to numerics this machine cannot honour (recorded per run)",
    )
    how.add_argument(
        "--advisor-check",
        choices=("require", "record", "skip"),
        default="require",
        help="the agent runs' advisor is checked first (greedy on 10 fresh episodes and from "
        "the states where it advises: mean reward >= 2.5, no action more than 10 times in a "
        "row); require (default): a given advisor that fails is refused and a trained one is "
        "trained again from the next seed (at most --advisor-attempts); record: checked, used "
        "anyway (needed for the agent method at reduced scales, where an advisor trained so "
        "briefly never passes); skip. Every advisor trained is left out of the report's "
        "agents",
    )
    how.add_argument(
        "--advisor-attempts",
        type=int,
        default=3,
        help="advisors the batch trains at most to get one that passes (default 3)",
    )
    how.add_argument("--report", type=Path, metavar="DIR", help="write the report at the end")
    how.add_argument(
        "--dry-run", action="store_true", help="show the runs and their state; write nothing"
    )
    how.add_argument(
        "--json", action="store_true", help="with --dry-run: the runs as JSON on stdout"
    )
    how.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_database_options(how)
    parser.set_defaults(func=batch)


def spec_from(
    args: argparse.Namespace, stored_model: Callable[[str], str] | None = None
) -> BatchSpec:
    """The batch the arguments describe, every run checked (`BatchError` otherwise); a
    `fitted_model` given as `fitted:ID` or an `advisor_checkpoint` as `session:ID` is the
    file `stored_model` finds for it."""
    from runs.batch import BatchError, BatchSpec

    declaration = declared()
    by_name = {leaf.name: leaf for leaf in leaves(declaration)}
    try:
        values = given_values(args, declaration)
        if args.run_file is not None:
            template = declaration.from_json(_document(args.run_file)).with_values(values)
        else:
            values.setdefault("torch_threads", 1)  # a batch fills the cores with 1-thread runs
            template = declaration.from_json(nest(values, declaration))
        fitted, advisor = template.fitted_model, template.advisor_checkpoint
        if fitted is not None and fitted.startswith("fitted:") and stored_model is not None:
            template = template.replace(fitted_model=stored_model(fitted))
        if advisor is not None and advisor.startswith("session:") and stored_model is not None:
            template = template.replace(advisor_checkpoint=stored_model(advisor))
        per_method: dict[str, dict[str, Any]] = {}
        for method, name, text in args.per_method:
            if name not in by_name or name == "method":
                raise FieldError(name, f"--per-method: unknown field {name[:64]}")
            per_method.setdefault(method, {})[name] = parse_text(by_name[name], text)
    except FieldError as error:
        raise BatchError(str(error)) from None
    return BatchSpec(
        template=template,
        methods=_methods(args.methods),
        agents=args.agents,
        label=args.label,
        per_method=per_method,
        control_of=args.control_of,
        replay_study=getattr(args, "replay_study", None),
        replay_methods=_methods([getattr(args, "replay_methods", "human")]),
    )


def _document(path: Path) -> Any:
    """A run's JSON document from a file ('-': standard input)."""
    from runs.batch import BatchError

    try:
        text = sys.stdin.read() if str(path) == "-" else path.read_text()
        return json.loads(text)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise BatchError(f"--run {path}: not a readable JSON document ({error})") from None


def command_line(args: argparse.Namespace, spec: BatchSpec) -> str:
    """The command that reruns (or resumes) exactly this batch, every choice spelled out."""
    parts = ["ideeprl", "batch", "--study", str(args.study), "--methods", *spec.methods]
    parts += ["--agents", str(spec.agents), "--label", spec.label]
    if "procedure" in spec.methods:
        parts += ["--control-of", spec.control_of]
    if spec.replay_study is not None:
        parts += ["--replay-study", str(spec.replay_study)]
        parts += ["--replay-methods", ",".join(spec.replay_methods)]
    parts += run_flags(spec.template, normalized=False)
    for method, changes in spec.per_method.items():
        for name, value in changes.items():
            text = value if isinstance(value, str) else json.dumps(value)
            parts += ["--per-method", f"{method}:{name}={text}"]
    parts += ["--backend", args.backend]
    if args.address:
        parts += ["--address", args.address]
    if args.workers:
        parts += ["--workers", str(args.workers)]
    if args.population:
        parts += ["--population", str(args.population)]
    parts += ["--checkpoint-every", str(args.checkpoint_every)]
    if args.nice:
        parts += ["--nice", str(args.nice)]
    if args.override_numerics:
        parts += ["--override-numerics"]
    if args.advisor_check != "require":
        parts += ["--advisor-check", args.advisor_check]
    if args.advisor_attempts != 3:
        parts += ["--advisor-attempts", str(args.advisor_attempts)]
    if args.data_dir:
        parts += ["--data-dir", str(args.data_dir)]
    if args.database_url:
        from sqlalchemy.engine import make_url

        parts += ["--database-url", make_url(args.database_url).render_as_string()]
    if args.report:
        parts += ["--report", str(args.report)]
    return shlex.join(parts)


def resolve_study(db: Session, study: str, create: bool = True) -> tuple[int | None, str]:
    """The study named by id or name; a new name creates the study (unless not `create`:
    then its id is None). Returns (id, what)."""
    from sqlalchemy import select

    from study.db.models import Study
    from study.services.studies import create_study

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
    if not create:
        return None, f"new study {study!r} (not created: dry run)"
    created = create_study(db, study, description="Baselines run in batch.")
    return created.id, f"new study {created.id} ({created.name})"


def _fail(message: str, code: int = 2) -> int:
    """Exit 2 for options that make no sense, 1 (`code=1`) for what went wrong running."""
    print(f"error: {message}", file=sys.stderr)
    return code


def batch(args: argparse.Namespace) -> int:
    from runs.batch import BatchError
    from study.db.engine import make_engine, make_session_factory
    from study.db.migrate import BACKUPS, upgrade
    from study.services.errors import ServiceError

    try:
        _check_counts(args)
        spec = spec_from(args, lambda name: _stored_model(name, settings_from(args)))
    except BatchError as error:
        return _fail(str(error))
    except ServiceError as error:
        return _fail(error.message, service_exit_code(error))
    settings = settings_from(args)
    if args.dry_run:
        return _dry_run(args, spec, settings)
    engine = make_engine(settings.db_url)
    upgrade(engine, settings.data_dir / BACKUPS)
    try:
        with make_session_factory(engine)() as db:
            study_id, what = resolve_study(db, args.study)
        assert study_id is not None
        print(f"{what}, database {shown_url(settings.db_url)}")
        return _run(args, spec, study_id, settings)
    except LookupError as error:
        return _fail(str(error), 1)
    except ServiceError as error:
        return _fail(error.message, service_exit_code(error))
    except BatchError as error:
        return _fail(str(error))


def _stored_model(name: str, settings: Settings) -> str:
    """The file `fitted:ID` (a stored fitted model, written again if gone) or `session:ID`
    (a session's checkpoint, its advisor) names, as a session's run through the API
    resolves it."""
    from study.db.engine import make_session_factory
    from study.services.fitted_files import resolve
    from study.services.sessions import advisor_path

    with make_session_factory(existing_database(settings))() as db:
        if name.startswith("session:"):
            return advisor_path(db, name, None)
        return resolve(db, name, settings.data_dir)


def _dry_run(args: argparse.Namespace, spec: BatchSpec, settings: Settings) -> int:
    """Each run and the session it has, writing nothing: no database, study or session is
    created, no migration is run."""
    from sqlalchemy import inspect

    from runs.batch.runner import BatchRunner, PreviewRow
    from runs.batch.spec import plan_runs
    from study.db.engine import make_engine, make_session_factory

    url = settings.db_url
    engine = None if _missing_sqlite(url) else make_engine(url)
    study_id, what = None, f"new study {args.study!r} (not created: dry run)"
    try:
        if engine is not None and inspect(engine).has_table("sessions"):
            with make_session_factory(engine)() as db:
                study_id, what = resolve_study(db, args.study, create=False)
        elif args.study.isdigit():  # as the real run would say: an id names no new study
            raise LookupError(
                f"no study with id {args.study}; there are no studies yet. Give a name "
                "instead to create a study"
            )
    except LookupError as error:
        return _fail(str(error), 1)
    if study_id is None:
        rows = [PreviewRow(run.name, run.method, run.seed) for run in plan_runs(spec)]
    else:
        options = _options(args, settings)
        runner = BatchRunner(spec, study_id, url, options, migrate=False)
        rows = runner.preview_rows()
    if args.json:
        runs = [dataclasses.asdict(row) for row in rows]
        print(json.dumps({"study": study_id, "database": shown_url(url), "runs": runs}, indent=2))
        return 0
    print(f"{what}, database {shown_url(url)}")
    for row in rows:
        head = f"  {row.run:<18} seed {row.seed:<8}"
        state = f"session {row.session}: {row.status}" if row.session else row.status
        print(f"{head} {state}")
    return 0


def _missing_sqlite(url: str) -> bool:
    from sqlalchemy.engine import make_url

    parsed = make_url(url)
    return parsed.get_backend_name() == "sqlite" and not Path(parsed.database or "").is_file()


def _check_counts(args: argparse.Namespace) -> None:
    from runs.batch import BatchError

    for flag, value, low in (
        ("--workers", args.workers, 1),
        ("--population", args.population, 1),
        ("--checkpoint-every", args.checkpoint_every, 1),
    ):
        if value is not None and value < low:
            raise BatchError(f"{flag} must be at least {low}")
    if not 0 <= args.nice <= 19:
        raise BatchError("--nice must be between 0 and 19")
    if args.address and args.backend != "ray":
        raise BatchError("--address is for the Ray backend: add --backend ray")
    if not 1 <= args.advisor_attempts <= 100:
        raise BatchError("--advisor-attempts must be between 1 and 100")
    if args.json and not args.dry_run:
        raise BatchError("--json goes with --dry-run")


def _options(args: argparse.Namespace, settings: Settings) -> RunnerOptions:
    from runs.batch import RunnerOptions

    return RunnerOptions(
        data_dir=settings.data_dir,
        backend=args.backend,
        workers=args.workers,
        population=args.population,
        address=args.address,
        checkpoint_every_episodes=args.checkpoint_every,
        heartbeat_s=settings.heartbeat_s,
        stale_after_s=settings.stale_after_s,
        nice=args.nice,
        progress=show_progress(args.no_progress),
        override_numerics=args.override_numerics,
        advisor_check=args.advisor_check,
        advisor_attempts=args.advisor_attempts,
    )


def _run(args: argparse.Namespace, spec: BatchSpec, study_id: int, settings: Settings) -> int:
    from runs.batch import describe
    from runs.batch.runner import BatchRunner

    runner = BatchRunner(spec, study_id, settings.db_url, _options(args, settings))
    result = runner.run()
    print("\n".join(describe(result)))
    if result.interrupted or not result.complete:
        print(f"to finish the batch, run the same command again:\n  {command_line(args, spec)}")
        return 130 if result.interrupted else 1
    print(f"all {len(result.runs)} runs finished in study {study_id} ({result.wall_time_s:.0f} s)")
    if args.report:
        return _report(args, spec, result, settings)
    print(f"report: {report_command(args, spec, result, settings)}")
    return 0


def report_command(
    args: argparse.Namespace, spec: BatchSpec, result: BatchResult, settings: Settings
) -> str:
    """The `ideeprl report` of exactly this batch's runs: by its label when every run has
    it, else by session (a batch takes over finished runs of the same description that an
    earlier batch made under another label)."""
    from sqlalchemy import select

    from study.db.engine import make_engine, make_session_factory
    from study.db.models import StudySession

    ids = result.session_ids()
    with make_session_factory(make_engine(settings.db_url))() as db:
        labels = set(db.scalars(select(StudySession.label).where(StudySession.id.in_(ids))))
    parts = ["ideeprl", "report", "--study", str(result.study_id)]
    if labels == {spec.label}:
        parts += ["--label", spec.label]
    else:
        parts += ["--sessions", *map(str, sorted(ids))]
    parts += ["--out", "DIR"]
    if args.data_dir:
        parts += ["--data-dir", str(args.data_dir)]
    if args.database_url:
        from sqlalchemy.engine import make_url

        parts += ["--database-url", make_url(args.database_url).render_as_string()]
    return shlex.join(parts)


def _report(
    args: argparse.Namespace, spec: BatchSpec, result: BatchResult, settings: Settings
) -> int:
    from runs.batch.provenance import describe_times, environment, training_times
    from study.db.engine import make_engine, make_session_factory
    from study.services.reports import ReportRequest, build_report

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
