"""`ideeprl rehearse --model FILE --link URL [--link URL ...]`: rehearse a study's load with
fitted advisors (`ideeprl fit`) answering human sessions through the participant links,
as people would: consent, the induction's Start, then each advice after its drawn
decision time, leaving early as often as the fitted people did (`runs.rehearsal`).
Create the human sessions first (dashboard, or POST /api/studies/ID/sessions) and pass
their links; each simulated participant runs in its own thread. The model's task is the
sessions' (the grid world's people are rehearsed with a model fitted to a grid world study)."""

from __future__ import annotations

import argparse
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
        "--link", dest="links", type=_link, action="append", required=True,
        metavar="URL", help="a human session's participant link (repeatable)",
    )  # fmt: skip
    parser.add_argument("--sort-rule", default="color", help="the study's sort rule (task sorting)")
    parser.add_argument("--seed", type=int, default=0, help="participant i draws with seed+i")
    parser.add_argument(
        "--speed", type=float, default=1.0,
        help="divide the waits by this (the decision times sent stay the drawn ones)",
    )  # fmt: skip
    add_json_option(parser, "each participant's advice, decision times and leaving")
    parser.set_defaults(func=rehearse_command)


def rehearse_command(args: argparse.Namespace) -> int:
    import httpx

    from learner.fitted import read_model
    from runs.rehearsal import rehearse

    if not args.speed > 0:
        raise CommandError("--speed must be above 0", code=2)
    try:
        model = read_model(args.model)
    except ValueError as error:
        raise CommandError(str(error), code=2) from None

    def one(i: int) -> Any:
        base, token = args.links[i]
        return rehearse(base, token, model, args.sort_rule, args.seed + i, args.speed)

    try:
        with ThreadPoolExecutor(max_workers=len(args.links)) as pool:
            done = list(pool.map(one, range(len(args.links))))
    except (RuntimeError, OSError, httpx.HTTPError) as error:
        raise CommandError(f"the rehearsal stopped: {error}") from None
    if args.json:
        print_json({"participants": [asdict(r) for r in done]})
        return 0
    for r in done:
        left = ", left early" if r.left_early else ""
        print(f"participant ...{r.token_tail}: {r.advice} advice{left}; session {r.status}")
    return 0
