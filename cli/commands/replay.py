"""`ideeprl replay`: re-run a recorded session as a new session, fed its advice by order.

Unchanged, a replay checks the platform's determinism on a researcher's own data: its steps
must equal the original's in every column that decides the run's course. Changed (another
preset, strategy, reward scheme, seed: the run's flags, as `ideeprl batch` has them), it
asks what the same advice does to another learner.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cli.commands.batch import add_database_options, settings_from
from cli.commands.common import (
    EXIT_USAGE,
    CommandError,
    add_json_option,
    add_set_option,
    given_values,
    print_json,
    service_exit_code,
)
from learner.fields import FieldError
from learner.fields import add_arguments as add_spec_arguments
from learner.run import RunSpec

if TYPE_CHECKING:
    from sqlalchemy.orm import Session

    from study.services.replays import Stream

DESCRIPTION = """\
Re-run a recorded session as a new session of a study (method `replayed`): the i-th advice
the session recorded goes to the i-th request of the new run, whatever state it meets; each
replayed advice records whether it met the image its advisor saw, and requests beyond the
recorded stream get no advice (the advice table logs them without an action). A session of
evaluative feedback replays its ratings the same way: the i-th rating it recorded (good,
bad or no answer) judges the i-th action the new run is asked about, and requests beyond
the stream get no answer (the feedback table logs each, with the image's hash).

Without run flags the replay is unchanged: on the CPU kind and numerics the original
recorded, its steps equal the original's in every deciding column (actions, action sources,
advised actions, rewards, terminations, observation hashes), and the command says so, or
exits 1 at the first difference; on another machine it says why records may differ.
With run flags (--preset authors, --strategy alternating, --reward-scheme ..., --seed ...)
the same advice goes to another run.

The source is a session of this database (--session ID), or of a study export
(--export FILE_OR_FOLDER --session ID, then --study names the study the replay joins)."""


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "replay",
        help="re-run a recorded session, fed its advice by order (unchanged: a check of "
        "determinism; changed: the same advice, another learner)",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    what = parser.add_argument_group("what to replay")
    what.add_argument("--session", type=int, required=True, help="the recorded session's id")
    what.add_argument(
        "--export",
        type=Path,
        metavar="FILE",
        help="read the session from a study export (its zip or folder) instead of the database",
    )
    what.add_argument(
        "--study",
        help="study (id or name; a new name creates it) the replay joins; default the "
        "source's own study (required with --export)",
    )
    what.add_argument("--label", default="", help="the replay's session label")
    run = parser.add_argument_group(
        "changes to the run",
        "every field of learner.run.RunSpec, one flag each (or --set FIELD=VALUE); none: the "
        "original's run unchanged",
    )
    add_spec_arguments(run, RunSpec, skip=("method",))
    add_set_option(what, "change any field of the run by its name")
    how = parser.add_argument_group("how to run it")
    how.add_argument(
        "--no-run", action="store_true", help="create the replay's session, do not run it"
    )
    how.add_argument(
        "--override-numerics",
        action="store_true",
        help="run on this machine's numerics where it cannot honour the original's (recorded)",
    )
    add_json_option(how, "the replay's session, its advice and the comparison")
    add_database_options(how)
    parser.set_defaults(func=replay)


def replay(args: argparse.Namespace) -> int:
    from study.db.engine import make_session_factory
    from study.services import replays
    from study.services.errors import ServiceError

    if args.export is not None and args.study is None:
        raise CommandError("--export needs --study: the study the replay joins", EXIT_USAGE)
    try:
        values = given_values(args, RunSpec)
    except FieldError as error:
        raise CommandError(str(error), EXIT_USAGE) from None
    settings = settings_from(args)
    engine = _database(settings, create=args.study is not None)
    factory = make_session_factory(engine)
    try:
        with factory() as db:
            stream = (
                replays.stream_of_export(args.export, args.session)
                if args.export is not None
                else replays.stream_of_session(db, args.session)
            )
            study_id = _target_study(db, args, stream)
            run = replays.replay_run(stream.run, values)
            session = replays.create_replay(db, study_id, stream, run, args.label)
            replay_id = session.id
    except ServiceError as error:
        raise CommandError(error.message, service_exit_code(error)) from None
    note = replays.why_records_may_differ(stream, run)
    result: dict[str, Any] = {
        "session_id": replay_id,
        "study_id": study_id,
        "source": stream.source,
        "unchanged": replays.unchanged(stream, run),
        "changed": _changed(stream.run, run),
        "recorded_ratings" if stream.rates else "recorded_advice": len(stream.actions),
        "why_records_may_differ": note,
    }
    if args.no_run:
        return _report(args, result)
    status = _run(replay_id, settings, args.override_numerics)
    result["status"] = status
    with factory() as db:
        summary = (
            replays.ratings_summary(db, replay_id, stream)
            if stream.rates
            else replays.advice_summary(db, replay_id)
        )
        result["ratings" if stream.rates else "advice"] = vars(summary)
        if result["unchanged"] and stream.steps:
            comparison = replays.compare(
                stream.steps, replays.replay_steps(db, replay_id), stream.finished
            )
            result["comparison"] = {"steps": comparison.steps, "difference": comparison.difference}
    return _report(args, result)


def _database(settings: Any, create: bool) -> Any:
    """The database `serve` uses (a replay into a new study may create its file)."""
    from cli.commands.common import existing_database

    if not create:
        return existing_database(settings)
    from study.db.engine import make_engine
    from study.db.migrate import BACKUPS, upgrade

    engine = make_engine(settings.db_url)
    upgrade(engine, settings.data_dir / BACKUPS)
    return engine


def _target_study(db: Session, args: argparse.Namespace, stream: Stream) -> int:
    from cli.commands.batch import resolve_study
    from study.db.models import StudySession

    if args.study is None:
        source = db.get(StudySession, args.session)
        assert source is not None
        return source.study_id
    try:
        study_id, _ = resolve_study(db, args.study)
    except LookupError as error:
        raise CommandError(str(error)) from None
    assert study_id is not None
    return study_id


def _changed(original: RunSpec, run: RunSpec) -> list[str]:
    """The run's fields that differ from the original's (its method aside)."""
    mine = original.normalized().values()
    theirs = run.normalized().values()
    skip = {"method", "advisor_checkpoint", "error_rate"}
    return sorted(k for k in theirs if k not in skip and mine.get(k) != theirs[k])


def _run(session_id: int, settings: Any, override_numerics: bool) -> str:
    from runs.worker.worker import WorkerOptions, run_session
    from study.services.errors import ServiceError

    options = WorkerOptions(
        data_dir=settings.data_dir,
        heartbeat_s=settings.heartbeat_s,
        override_numerics=override_numerics,
    )
    try:
        return run_session(session_id, settings.db_url, options)
    except ServiceError as error:
        raise CommandError(error.message, service_exit_code(error)) from None


def _report(args: argparse.Namespace, result: dict[str, Any]) -> int:
    """Print what the replay did; exit 1 when an unchanged replay differs from its original
    on the machine and numerics the original recorded (a fault), or it did not finish."""
    comparison = result.get("comparison")
    fault = (
        comparison is not None
        and comparison["difference"] is not None
        and result["why_records_may_differ"] is None
    )
    unfinished = "status" in result and result["status"] != "finished"
    if args.json:
        print_json({**result, "fault": fault})
        return 1 if fault or unfinished else 0
    source = result["source"]
    where = f" of export {source['export']}" if source.get("export") else ""
    rates = "recorded_ratings" in result
    recorded = result["recorded_ratings" if rates else "recorded_advice"]
    print(
        f"replay: session {result['session_id']} (study {result['study_id']}) of session "
        f"{source['session']}{where}, {recorded} recorded {'ratings' if rates else 'advice'}"
    )
    if result["changed"]:
        print(f"changed: {', '.join(result['changed'])}")
    if "status" not in result:
        print(f"not run (--no-run): session {result['session_id']} is created")
        return 0
    print(f"status: {result['status']}")
    advice = result["ratings" if rates else "advice"]
    seen = "the image they were given on" if rates else "the image their advisor saw"
    same = f"{advice['same_observation']} met {seen}"
    if advice["first_different"] is not None:
        same += f" (the first that did not: step {advice['first_different']})"
    print(f"{'ratings' if rates else 'advice'}: {advice['replayed']} replayed, {same}")
    if advice["beyond_stream"]:
        none = "no answer" if rates else "no advice (logged without an action)"
        print(f"beyond the stream: {advice['beyond_stream']} request(s) got {none}")
    note = result["why_records_may_differ"]
    if comparison is not None:
        difference = comparison["difference"]
        if difference is None:
            print(
                f"unchanged replay: its {comparison['steps']} steps equal the original's in "
                "every deciding column"
            )
        else:
            what = (
                f"step {difference['global_step']}, {difference['column']}: original "
                f"{difference['original']!r}, replay {difference['replay']!r}"
            )
            if fault:
                print(f"FAULT: the unchanged replay differs from its original at {what}")
            else:
                print(f"the unchanged replay differs from its original at {what}")
    if note and (result["unchanged"] or comparison is not None):
        print(f"records may differ from the original's: {note}")
    return 1 if fault or unfinished else 0
