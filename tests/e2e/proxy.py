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


def _main_config(folder: Path, http_body: str) -> str:
    """nginx.conf for a foreground nginx that writes only in `folder`."""
    temp = {k: folder / k for k in ("body", "proxy", "fastcgi", "uwsgi", "scgi")}
    for path in temp.values():
        path.mkdir(parents=True, exist_ok=True)
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
{http_body}
}}
"""


def config(folder: Path, listen_port: int, upstream_port: int) -> str:
    """Plain HTTP on loopback around the deployment's own proxy snippet."""
    return _main_config(
        folder,
        f"""    map $http_upgrade $connection_upgrade {{
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
    }}""",
    )


def tls_config(
    folder: Path, http_port: int, https_port: int, upstream_port: int, cert: Path, key: Path
) -> str:
    """The shipped site file (deploy/nginx/ideeprl.conf) as it is, but for its ports, paths
    and certificate: what docs/deploy.md tells a researcher to install."""
    site = SITE.read_text()
    for old, new in {
        "listen 80;": f"listen 127.0.0.1:{http_port};",
        "listen [::]:80;": "",
        "listen 443 ssl http2;": f"listen 127.0.0.1:{https_port} ssl http2;",
        "listen [::]:443 ssl http2;": "",
        "server 127.0.0.1:8000;": f"server 127.0.0.1:{upstream_port};",
        "/etc/letsencrypt/live/study.example.org/fullchain.pem": str(cert),
        "/etc/letsencrypt/live/study.example.org/privkey.pem": str(key),
        "/etc/nginx/snippets/ideeprl-proxy.conf": str(PROXY_SNIPPET),
    }.items():
        assert old in site, f"{SITE} no longer has {old!r}: update the test with the file"
        site = site.replace(old, new)
    (folder / "site.conf").write_text(site)
    return _main_config(folder, f"    include {folder / 'site.conf'};")


def self_signed(folder: Path, name: str = "localhost") -> tuple[Path, Path]:
    """A throw-away certificate and key, as `openssl req -x509` makes them."""
    cert, key = folder / "cert.pem", folder / "key.pem"
    subprocess.run(
        ["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "2",
         "-subj", f"/CN={name}", "-keyout", str(key), "-out", str(cert)],
        check=True, capture_output=True,
    )  # fmt: skip
    return cert, key


@contextmanager
def nginx(folder: Path, conf_text: str, probe: str) -> Iterator[None]:
    """nginx running `conf_text` in the foreground until the block ends; `probe` is a URL
    that answers once it is up."""
    folder.mkdir(parents=True, exist_ok=True)
    conf = folder / "nginx.conf"
    conf.write_text(conf_text)
    process = subprocess.Popen(
        [NGINX, "-p", str(folder), "-e", str(folder / "error.log"), "-c", str(conf)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    try:
        deadline = time.monotonic() + 30
        while True:
            if process.poll() is not None:
                log = (folder / "error.log").read_text() if (folder / "error.log").exists() else ""
                out = process.stdout.read().decode() if process.stdout else ""
                raise AssertionError(f"nginx exited ({process.returncode}): {out}{log}")
            try:
                httpx.get(probe, timeout=2, verify=False)
                break
            except httpx.TransportError:
                assert time.monotonic() < deadline, "nginx did not start"
                time.sleep(0.1)
        yield
    finally:
        process.send_signal(signal.SIGTERM)  # fast shutdown: open websockets are cut
        try:
            process.wait(20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(10)
        if process.stdout:
            process.stdout.close()
