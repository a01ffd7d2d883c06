"""`ideeprl serve`: run the study server (API, participant pages, session workers)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "serve",
        help="run the study server",
        description="Run the study server. Settings come from IDEEPRL_* environment "
        "variables or .env (see docs/api.md); these options override them.",
    )
    parser.add_argument("--host", help="interface to listen on (default 127.0.0.1)")
    parser.add_argument("--port", type=int, help="port (default 8000)")
    parser.add_argument(
        "--public-url",
        help="address participants reach the server at, for their links (default http://HOST:PORT)",
    )
    parser.add_argument("--data-dir", type=Path, help="folder of database, checkpoints, exports")
    parser.add_argument(
        "--ray-address",
        help="a Ray cluster that trains participants' learners after their advice "
        "(needs PostgreSQL and a storage root every node sees; docs/deploy.md)",
    )
    parser.add_argument("--log-level", default="info", help="uvicorn log level")
    parser.set_defaults(func=serve)


def serve(args: argparse.Namespace) -> int:
    import uvicorn

    from cli.commands.common import CommandError, check_database, shown_url
    from server.main import UVICORN_OPTIONS, StartRefused, create_app
    from study.settings import Settings

    overrides = {
        k: v
        for k, v in {
            "host": args.host,
            "port": args.port,
            "public_url": args.public_url,
            "data_dir": args.data_dir,
            "ray_address": args.ray_address,
        }.items()
        if v is not None
    }
    settings = Settings(**overrides)
    key, new = settings.ensure_api_key()
    try:
        app = create_app(settings)
    except StartRefused as error:
        raise CommandError(f"the server does not start: {error}", code=2) from None
    base = settings.base_url
    where = settings.data_dir / "api_key"
    if sys.stdout.isatty():
        shown, example = key + (f" (new, saved in {where})" if new else ""), key
    else:
        # a service's output goes to its journal, which more people read than the key's
        # 0600 file: say where the key is, never the key
        saved = where.exists() and where.read_text().strip() == key
        shown = f"in {where} (its owner's alone)" if saved else "the IDEEPRL_API_KEY you set"
        example = "KEY"
    print(
        f"IDeepRL study server\n"
        f"  dashboard:       {base}/dashboard (log in with the researcher key)\n"
        f"  API docs:        {base}/docs\n"
        f"  API:             {base}/api\n"
        f"  participant URL: {base}/p/TOKEN (each human session has its own link)\n"
        f"  database:        {shown_url(settings.db_url)}\n"
        f"  researcher key:  {shown}\n"
        f"  send it as the X-API-Key header, e.g.\n"
        f"  curl -H 'X-API-Key: {example}' {base}/api/studies",
        flush=True,
    )
    check_database(settings.db_url)
    uvicorn.run(
        app,
        host=settings.host,
        port=settings.port,
        log_level=args.log_level,
        forwarded_allow_ips=settings.forwarded_allow_ips,
        **UVICORN_OPTIONS,
    )
    return 0
