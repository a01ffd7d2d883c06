"""`ideeprl outcomes --study ID|NAME`: fill in the steps' outcomes of logs recorded before
they were kept, by replaying each episode from its reset seed (`study.services.outcomes`),
so that rescoring reads what each step did rather than guessing it from the rewards."""

from __future__ import annotations

import argparse
from typing import Any

from cli.commands.batch import add_database_options, settings_from
from cli.commands.common import add_json_option, existing_database, find_study, print_json


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "outcomes",
        help="fill in old step logs' outcomes (placed, misplaced, lost) by replaying them",
        description=__doc__,
    )
    parser.add_argument("--study", required=True, help="study id or name")
    add_json_option(parser, "each session's filled steps and replayed episodes")
    add_database_options(parser)
    parser.set_defaults(func=outcomes)


def outcomes(args: argparse.Namespace) -> int:
    from sqlalchemy import select

    from study.db.engine import make_session_factory
    from study.db.models import StudySession
    from study.services.outcomes import fill_outcomes

    engine = existing_database(settings_from(args))
    done = []
    with make_session_factory(engine)() as db:
        study_id, _ = find_study(db, args.study)
        query = select(StudySession).where(StudySession.study_id == study_id)
        for session in list(db.scalars(query.order_by(StudySession.id))):
            filled = fill_outcomes(db, session)
            done.append(vars(filled))
            if not args.json:
                seedless = filled.without_seed
                extra = f", {seedless} without a reset seed" if seedless else ""
                print(
                    f"session {filled.session_id}: {filled.steps} steps filled in "
                    f"({filled.episodes} episodes replayed{extra})"
                )
    if args.json:
        print_json({"study_id": study_id, "sessions": done})
    return 0
