"""`ideeprl study create --from design.yaml`: an online study from a file, as
`POST /api/studies` makes it (the same body: name, description, texts, design), written
into the database `serve` uses. The file is YAML (JSON is YAML too)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from cli.commands.batch import add_database_options, settings_from
from cli.commands.common import EXIT_USAGE, CommandError, add_json_option, print_json


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "study", help="create a study (an online one from a design file)", description=__doc__
    )
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    create = actions.add_parser("create", help="create a study from a YAML file")
    create.add_argument(
        "--from",
        dest="source",
        type=Path,
        required=True,
        help="YAML file: name, description, texts and design (conditions, targets, "
        "capacity, alpha, idle_limit_s, panel, check, questionnaire)",
    )
    create.add_argument("--name", help="the study's name (instead of the file's)")
    create.add_argument(
        "--public-url",
        help="address participants reach the server at, for the printed link (as `ideeprl "
        "serve --public-url`; default IDEEPRL_PUBLIC_URL, else http://127.0.0.1:8000)",
    )
    add_json_option(create, "the study as the API returns it")
    add_database_options(create)
    create.set_defaults(func=create_study)


def read_body(source: Path, name: str | None) -> Any:
    """The file as a `StudyCreate` body; a bad file is a usage error naming every bad value
    by its field (as the API's 422 does), one a line: pydantic's, and each condition's run's
    (checked as the study is made, so a file is not fixed one value at a time)."""
    import yaml
    from pydantic import ValidationError

    from study.schemas.studies import StudyCreate

    try:
        data = yaml.safe_load(source.read_text())
    except (OSError, yaml.YAMLError) as error:
        raise CommandError(f"cannot read {source}: {error}", EXIT_USAGE) from None
    if not isinstance(data, dict):
        raise CommandError(f"{source} must hold a mapping (name:, design:, ...)", EXIT_USAGE)
    if name:
        data["name"] = name
    body = None
    problems: list[str] = []
    try:
        body = StudyCreate.model_validate(data)
    except ValidationError as error:
        schema = StudyCreate.model_json_schema()
        problems = [_problem(schema, e) for e in error.errors()]
    runs = _run_problems(data)  # in the service's words, as the API's 422 gives them
    problems = [p for p in problems if not _in_a_condition_run(p)] + runs
    if len(problems) == 1:
        raise CommandError(f"{source}: {problems[0]}", EXIT_USAGE)
    if problems:
        lines = "".join(f"\n  {problem}" for problem in problems)
        raise CommandError(f"{source}: {len(problems)} bad values:{lines}", EXIT_USAGE)
    return body


def _problem(schema: dict[str, Any], error: Any) -> str:
    """One of pydantic's errors as the API's 422 words it: `design.capacity: ...`."""
    from study.schemas.errors import readable, unknown_field, valid_fields

    loc = error["loc"]
    message = error["msg"]
    if error["type"] == "extra_forbidden" and loc:
        message = unknown_field(str(loc[-1]), valid_fields(schema, loc[:-1]))
    where = ".".join(str(readable(part)) for part in loc)
    return f"{where}: {message}" if where else message


def _in_a_condition_run(problem: str) -> bool:
    parts = problem.split(": ", 1)[0].split(".")
    return parts[:2] == ["design", "conditions"] and parts[3:4] == ["run"] and len(parts) > 4


def _run_problems(data: dict[str, Any]) -> list[str]:
    """What is wrong with each condition's run as the service checks it (its values, which
    pydantic names too, and the rules between them, which only the service knows), named
    `design.conditions.NAME.run.FIELD`."""
    from study.services.errors import Invalid
    from study.services.studies import condition_run

    design = data.get("design")
    conditions = design.get("conditions") if isinstance(design, dict) else None
    problems = []
    for name, condition in (conditions if isinstance(conditions, dict) else {}).items():
        run = condition.get("run") if isinstance(condition, dict) else None
        if isinstance(run, dict):
            try:
                condition_run(str(name), run)
            except Invalid as error:
                problems.append(f"{error.field}: {error.message}")
    return problems


def create_study(args: argparse.Namespace) -> int:
    from study.db.engine import make_engine, make_session_factory
    from study.db.migrate import BACKUPS, upgrade
    from study.schemas.studies import StudyPublic
    from study.services import studies
    from study.services.errors import Invalid, ServiceError

    body = read_body(args.source, args.name)
    settings = settings_from(args)
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    engine = make_engine(settings.db_url)
    upgrade(engine, settings.data_dir / BACKUPS)
    with make_session_factory(engine)() as db:
        try:
            study = studies.create_study(
                db, body.name, description=body.description, texts=body.texts, design=body.design
            )
        except ServiceError as error:
            if isinstance(error, Invalid):
                raise CommandError(f"{error.field}: {error.message}", EXIT_USAGE) from None
            raise CommandError(error.message) from None
        # what GET /api/studies/ID answers (`server.routes.studies.study_public`), built
        # here: one command need not load the web process's modules
        update = {
            "session_count": studies.session_count(db, study.id),
            "join_url": studies.join_url(study, args.public_url or settings.base_url),
        }
        public = StudyPublic.model_validate(study).model_copy(update=update)
    engine.dispose()
    if args.json:
        print_json(public.model_dump(mode="json"))
        return 0
    print(f"study {public.id} ({public.name}) created")
    if public.join_url:
        print(f"its link: {public.join_url}")
        if not (args.public_url or settings.public_url):
            print(
                "(for a server at the default address; behind another one give --public-url "
                "or IDEEPRL_PUBLIC_URL, as `ideeprl serve` has it: the dashboard shows the "
                "link as the server sees it)"
            )
    return 0
