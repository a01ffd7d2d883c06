"""Debian's nginx in front of the study server, as docs/deploy.md sets it up: one port for
the API, the pages and the 3-D view's websocket. Run by the tests as a foreground process
with its own config in a temporary folder, on a random loopback port."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx

ROOT = Path(__file__).absolute().parents[2]
PROXY_SNIPPET = ROOT / "deploy" / "nginx" / "ideeprl-proxy.conf"
SITE = ROOT / "deploy" / "nginx" / "ideeprl.conf"
NGINX = shutil.which("nginx") or "/usr/sbin/nginx"


def nginx_available() -> bool:
    return Path(NGINX).exists()


def config(folder: Path, listen_port: int, upstream_port: int) -> str:
    """An nginx.conf around the deployment's own proxy snippet, writing only in `folder`."""
    temp = {k: folder / k for k in ("body", "proxy", "fastcgi", "uwsgi", "scgi")}
    for path in temp.values():
        path.mkdir(exist_ok=True)
    user = "user root;\n" if os.geteuid() == 0 else ""
    return f"""{user}worker_processes 1;
daemon off;
pid {folder}/nginx.pid;
error_log {folder}/error.log warn;
events {{ worker_connections 256; }}
http {{
    access_log off;
    client_body_temp_path {temp["body"]};
    proxy_temp_path {temp["proxy"]};
    fastcgi_temp_path {temp["fastcgi"]};
    uwsgi_temp_path {temp["uwsgi"]};
    scgi_temp_path {temp["scgi"]};
    map $http_upgrade $connection_upgrade {{
        default upgrade;
        ''      '';
    }}
    upstream ideeprl {{
        server 127.0.0.1:{upstream_port};
        keepalive 16;
    }}
    server {{
        listen 127.0.0.1:{listen_port};
        include {PROXY_SNIPPET};
    }}
}}
"""


@contextmanager
def nginx(folder: Path, listen_port: int, upstream_port: int) -> Iterator[str]:
    """nginx on 127.0.0.1:`listen_port` proxying to `upstream_port`; yields its base URL."""
    folder.mkdir(parents=True, exist_ok=True)
    conf = folder / "nginx.conf"
    conf.write_text(config(folder, listen_port, upstream_port))
    process = subprocess.Popen(
        [NGINX, "-p", str(folder), "-e", str(folder / "error.log"), "-c", str(conf)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    url = f"http://127.0.0.1:{listen_port}"
    try:
        deadline = time.monotonic() + 30
        while True:
            if process.poll() is not None:
                log = (folder / "error.log").read_text() if (folder / "error.log").exists() else ""
                out = process.stdout.read().decode() if process.stdout else ""
                raise AssertionError(f"nginx exited ({process.returncode}): {out}{log}")
            try:
                httpx.get(f"{url}/api/health", timeout=2)
                break
            except httpx.TransportError:
                assert time.monotonic() < deadline, "nginx did not start"
                time.sleep(0.1)
        yield url
    finally:
        process.send_signal(signal.SIGTERM)  # fast shutdown: open websockets are cut
        try:
            process.wait(20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(10)
        if process.stdout:
            process.stdout.close()
