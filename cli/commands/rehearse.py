"""`ideeprl rehearse --model FILE --link URL [--link URL ...]` (or `--study-link URL
--participants N`, an online study's whole visits): rehearse a study's load with
fitted advisors or evaluators (`ideeprl fit`) answering human sessions through the
participant links,
as people would: consent, the induction's Start, then each advice (or, under evaluative
feedback, each rating) after its drawn decision time, leaving early as often as the fitted
people did (`runs.rehearsal`); a summary per kind of feedback.
Create the human sessions first (dashboard, or POST /api/studies/ID/sessions) and pass
their links; each simulated participant runs in its own thread. The model's task is the
sessions' (the grid world's people are rehearsed with a model fitted to a grid world study).
An online study's comprehension check is answered right where the rehearsal knows the
answers: the task's built-in questions, and the study's own, read from the study's design
(`--design`, the file `ideeprl study create --from` read, or else through the researcher
API with the researcher's key: `--api-key`, or IDEEPRL_API_KEY). It never guesses: given
neither, a check with questions of the study's own stops the rehearsal at its first
participant, before anyone answers, naming the questions. `--check-failures SHARE` of the
participants answer it wrong on every try and are excluded as the check says."""

from __future__ import annotations

import argparse
import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from cli.commands.common import CommandError, add_json_option, print_json


def _link(text: str) -> tuple[str, str]:
    """(the server's base URL, the token) of a participant link `http://host/p/TOKEN`."""
    parts = urlsplit(text)
    prefix, _, token = parts.path.rpartition("/p/")
    if not parts.scheme or not parts.netloc or not token or "/" in token:
        raise argparse.ArgumentTypeError("--link takes a participant link, http://HOST/p/TOKEN")
    return f"{parts.scheme}://{parts.netloc}{prefix}", token


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "rehearse",
        help="rehearse a study's load: fitted advisors answer human sessions by their links",
        description=__doc__,
    )
    parser.add_argument("--model", type=Path, required=True, help="a fitted model's JSON file")
    parser.add_argument(
        "--link", dest="links", type=_link, action="append", default=[],
        metavar="URL", help="a human session's participant link (repeatable)",
    )  # fmt: skip
    parser.add_argument(
        "--study-link", metavar="URL",
        help="an online study's join link: --participants arrive through it, each with a "
        "panel id of its own, and go through the whole visit (check, questionnaire)",
    )  # fmt: skip
    parser.add_argument(
        "--participants", type=int, default=0, help="how many arrive through --study-link"
    )
    parser.add_argument(
        "--panel-param", default="PROLIFIC_PID",
        help="the study link's panel id parameter (the design's panel: Prolific's by default)",
    )  # fmt: skip
    parser.add_argument("--sort-rule", default="color", help="the study's sort rule (task sorting)")
    parser.add_argument(
        "--design", type=Path, metavar="FILE",
        help="the study's YAML file (as `ideeprl study create --from`): its own check "
        "questions are answered right",
    )  # fmt: skip
    parser.add_argument(
        "--api-key", default=os.environ.get("IDEEPRL_API_KEY"), metavar="KEY",
        help="the researcher key (default: IDEEPRL_API_KEY, which keeps it out of the "
        "process list): without --design, the study's check is read from its design "
        "through the researcher API",
    )  # fmt: skip
    parser.add_argument(
        "--check-failures", type=float, default=0.0, metavar="SHARE",
        help="the share of participants (0 to 1, spread evenly) who answer the check wrong "
        "on every try, and are excluded (default 0)",
    )  # fmt: skip
    parser.add_argument("--seed", type=int, default=0, help="participant i draws with seed+i")
    parser.add_argument(
        "--speed", type=float, default=1.0,
        help="divide the waits by this (the decision times sent stay the drawn ones)",
    )  # fmt: skip
    add_json_option(parser, "each participant's advice, decision times and leaving")
    parser.set_defaults(func=rehearse_command)


def rehearse_command(args: argparse.Namespace) -> int:
    import httpx

    from learner.fitted_ratings import read_any_model
    from runs.rehearsal import UnknownCheck, fails_check, join, rehearse, study_check

    if not args.speed > 0:
        raise CommandError("--speed must be above 0", code=2)
    if not 0 <= args.check_failures <= 1:
        raise CommandError("--check-failures takes a share from 0 to 1", code=2)
    if bool(args.study_link) != (args.participants > 0) or (args.links and args.study_link):
        raise CommandError(
            "pass participant links (--link URL ...), or an online study's link with how "
            "many arrive (--study-link URL --participants N)",
            code=2,
        )
    try:
        model = read_any_model(args.model)
    except ValueError as error:
        raise CommandError(str(error), code=2) from None
    check, known = None, False
    try:
        if args.design is not None:
            from cli.commands.study import read_body

            design = read_body(args.design, None).design
            check, known = (None if design is None else design.check), True
        elif args.api_key:
            link = args.study_link or "{}/p/{}".format(*args.links[0])
            check, known = study_check(link, args.api_key), True
    except (RuntimeError, OSError, httpx.HTTPError) as error:
        raise CommandError(f"the study's check could not be read: {error}") from None

    def one(i: int, on_check: Callable[[], None] | None = None) -> Any:
        if args.study_link:
            base, token = join(args.study_link, f"rehearsal-{args.seed + i}", args.panel_param)
        else:
            base, token = args.links[i]
        fail = fails_check(i, args.check_failures)
        return rehearse(base, token, model, args.sort_rule, args.seed + i, args.speed,
                        design_check=check, fail_check=fail, on_check=on_check)  # fmt: skip

    count = args.participants or len(args.links)
    try:
        with ThreadPoolExecutor(max_workers=count) as pool:
            if known:
                futures = [pool.submit(one, i) for i in range(count)]
            else:  # the first alone through the check, which may ask what it cannot answer
                checked = threading.Event()
                first = pool.submit(one, 0, checked.set)
                first.add_done_callback(lambda _: checked.set())
                checked.wait()
                if first.done() and first.exception() is not None:
                    first.result()
                futures = [first, *(pool.submit(one, i) for i in range(1, count))]
            done = [f.result() for f in futures]
    except UnknownCheck as error:
        if known:
            how = "the design it was given does not hold them: is it this study's?"
        else:
            how = (
                "give the study's design (--design FILE) or the researcher key (--api-key "
                "KEY, or IDEEPRL_API_KEY) to read it from the server; the first participant "
                "stopped at the check without answering, and no other arrived"
            )
        raise CommandError(f"{error}. {how}", code=2) from None
    except (RuntimeError, OSError, httpx.HTTPError) as error:
        raise CommandError(f"the rehearsal stopped: {error}") from None
    if args.json:
        print_json({"participants": [asdict(r) for r in done]})
        return 0
    for r in done:
        left = ", left early" if r.left_early else ""
        if r.feedback == "evaluative":
            given = f"{r.advice} ratings, {r.lapsed} without an answer"
        else:
            given = f"{r.advice} advice"
        visit = f", check in {r.check_tries}" if r.check_tries else ""
        visit += ", questionnaire" if r.questionnaire else ""
        print(f"participant ...{r.token_tail}: {given}{left}{visit}; session {r.status}")
    for kind in sorted({r.feedback for r in done}):
        these = [r for r in done if r.feedback == kind]
        times = sorted(t for r in these for t in r.decision_times_s)
        median = f"{times[len(times) // 2]:.2f} s" if times else "none"
        print(f"{kind}: {len(these)} participants, {sum(r.advice for r in these)} answered, "
              f"median decision time {median}")  # fmt: skip
    return 0
