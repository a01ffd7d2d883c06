"""`ideeprl fit --study ID|NAME [--methods human,oracle] [--kind advice|evaluative]
[--json]`: fit an advisor to a study's people (how often they were right by situation,
what they advised when wrong, their decision times, how much of their budget they used),
or, from its evaluative sessions, an evaluator (how often their ratings said what the
correct action says of the move, by move and situation, how often they gave no answer,
their decision times); store it with the study, and print its summary and the file a
`fitted` run names (`--method fitted --fitted-model FILE`, with `--feedback evaluative`
for an evaluator; or `fitted:ID` through the API). Replays each advised or rated episode
from its reset seed to know its situations (`study.services.fitting`)."""

from __future__ import annotations

import argparse
from typing import Any

from cli.commands.batch import add_database_options, settings_from
from cli.commands.common import (
    CommandError,
    add_json_option,
    existing_database,
    find_study,
    print_json,
    service_exit_code,
)


def _methods(text: str) -> tuple[str, ...]:
    return tuple(m.strip() for m in text.split(",") if m.strip())


def _ids(text: str) -> list[int]:
    try:
        return [int(n) for n in text.split(",") if n.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError("--sessions takes session ids: 3,4,7") from None


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "fit",
        help="fit an advisor (or evaluator) to a study's people and store it (method fitted "
        "advises, or rates, like it)",
        description=__doc__,
    )
    parser.add_argument("--study", required=True, help="study id or name")
    parser.add_argument(
        "--methods",
        type=_methods,
        default=("human",),
        metavar="M1,M2",
        help="the sessions' methods to fit (default human; human,oracle lets an oracle "
        "pilot with an error rate and decision times stand in for people)",
    )
    parser.add_argument(
        "--sessions",
        type=_ids,
        metavar="ID1,ID2",
        help="only these sessions (e.g. one participant's)",
    )
    parser.add_argument(
        "--kind",
        choices=("advice", "evaluative"),
        help="fit the sessions' advice (an advisor) or their ratings (an evaluator); "
        "default: the one kind the sessions gave",
    )
    add_json_option(parser, "the stored model's id, file, summary and whole model")
    add_database_options(parser)
    parser.set_defaults(func=fit)


def fit(args: argparse.Namespace) -> int:
    from study.db.engine import make_session_factory
    from study.services.errors import ServiceError
    from study.services.fitting import fit_study

    settings = settings_from(args)
    engine = existing_database(settings)
    with make_session_factory(engine)() as db:
        study_id, what = find_study(db, args.study)
        try:
            fitted = fit_study(
                db, settings.data_dir, study_id, args.methods, args.sessions, args.kind
            )
        except ServiceError as error:
            raise CommandError(error.message, service_exit_code(error)) from None
    summary = fitted.model.summary()
    result = {
        "id": fitted.id,
        "study_id": study_id,
        "path": str(fitted.path.resolve()),
        "without_situation": fitted.without_situation,
        "summary": summary,
        "model": fitted.model.to_json(),
    }
    if args.json:
        print_json(result)
        return 0
    if summary.get("kind") == "evaluative":
        return _print_evaluator(fitted.id, what, result)
    print(
        f"fitted advisor {fitted.id} of {what}: {summary['advice']} advice from "
        f"{summary['sessions']} session(s); file {result['path']}"
    )
    if fitted.without_situation:
        print(f"  {fitted.without_situation} advice left out: their episode has no record")
    print(
        f"  wrong: {summary['error_rate']:.3f} overall; by group: "
        + ", ".join(f"{h} {r:.3f}" for h, r in summary["error_rate_by_group"].items())
    )
    print(
        "  by situation: "
        + ", ".join(f"{k} {r:.3f}" for k, r in summary["error_rate_by_situation"].items())
    )
    median = summary["decision_time_median_s"]
    if median is not None:
        print(f"  decision time: median {median:.2f} s, sigma {summary['decision_time_sigma']:.2f}")
    print(f"  stopped before the budget's end: {summary['stop_early_rate']:.0%} of sessions")
    print(f"  use it: ideeprl batch --methods fitted --fitted-model {result['path']} ...")
    return 0


def _print_evaluator(model_id: int, what: str, result: dict[str, Any]) -> int:
    summary = result["summary"]
    print(
        f"fitted evaluator {model_id} of {what}: {summary['ratings']} rating turns "
        f"({summary['answered']} answered) from {summary['sessions']} session(s); file "
        f"{result['path']}"
    )
    if result["without_situation"]:
        print(f"  {result['without_situation']} turns left out: their episode has no record")
    by_move = summary["error_rate_by_move"]
    print(
        f"  wrong: {summary['error_rate']:.3f} overall; rating a right move "
        f"{by_move['right']:.3f}, a wrong one {by_move['wrong']:.3f}"
    )
    print(f"  Good: {summary['good_rate']:.3f} of answers; no answer: "
          f"{summary['no_answer_rate']:.3f} of turns")  # fmt: skip
    median = summary["decision_time_median_s"]
    if median is not None:
        print(f"  decision time: median {median:.2f} s, sigma {summary['decision_time_sigma']:.2f}")
    print(
        "  use it: ideeprl batch --methods fitted --feedback evaluative --fitted-model "
        f"{result['path']} ..."
    )
    return 0
