"""The deployment docs/deploy.md describes, run for real: the shipped nginx site file with
TLS in front of the study server serves the API, the offline API docs and the 3-D view's
websocket (upgraded through nginx, closed by the viewer for a forged token); and the API
docs draw in a browser cut off from the internet."""

from __future__ import annotations

import ssl
from urllib.parse import urlsplit

import httpx
import pytest
import viser
from playwright.sync_api import expect
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from server.viewer.connection import CLOSE_FORBIDDEN
from tests.e2e.conftest import Live
from tests.e2e.proxy import nginx, self_signed, tls_config
from tests.server.live import free_port

pytestmark = pytest.mark.slow


def test_the_shipped_nginx_site_serves_https_and_websockets(live: Live, tmp_path) -> None:
    cert, key = self_signed(tmp_path)
    http_port, https_port = free_port(), free_port()
    conf = tls_config(tmp_path, http_port, https_port, live.server_port, cert, key)
    base = f"https://127.0.0.1:{https_port}"
    with nginx(tmp_path, conf, f"{base}/api/health"):
        with httpx.Client(verify=False, timeout=30) as client:
            plain = client.get(f"http://127.0.0.1:{http_port}/api/health")
            assert plain.status_code == 301
            assert plain.headers["location"].startswith("https://")
            assert client.get(f"{base}/api/health").status_code == 200
            docs = client.get(f"{base}/docs")
            assert docs.status_code == 200 and "/docs-assets/swagger-ui-bundle.js" in docs.text
            bundle = client.get(f"{base}/docs-assets/swagger-ui-bundle.js")
            assert bundle.status_code == 200 and len(bundle.content) > 100_000
            page = client.get(f"{base}/viewer/")
            assert page.status_code == 200 and "ideeprl-participant" in page.text

        context = ssl.create_default_context()
        context.check_hostname = False
        context.verify_mode = ssl.CERT_NONE
        refused = live.app.state.viewer.refused
        with (
            connect(
                f"wss://127.0.0.1:{https_port}/viewer/p/{'x' * 43}",
                subprotocols=[f"viser-v{viser.__version__}"],
                ssl=context,
                open_timeout=30,
            ) as ws,
            pytest.raises(ConnectionClosed) as closed,
        ):
            ws.recv(timeout=30)
        assert closed.value.rcvd is not None and closed.value.rcvd.code == CLOSE_FORBIDDEN
        assert live.app.state.viewer.refused == refused + 1, "the viewer itself refused it"


LOOPBACK = {"localhost", "127.0.0.1", "::1", "[::1]"}


@pytest.mark.browser
def test_the_api_docs_work_without_internet(live: Live, browser) -> None:
    """Every request but to this machine is aborted, as on a study network without internet:
    Swagger UI still draws the API from the files the server holds."""
    context = browser.new_context()
    blocked: list[str] = []

    def only_loopback(route) -> None:
        if urlsplit(route.request.url).hostname in LOOPBACK:
            route.continue_()
        else:
            blocked.append(route.request.url)
            route.abort()

    context.route("**/*", only_loopback)
    page = context.new_page()
    page.goto(f"{live.url}/docs")
    expect(page.locator(".swagger-ui .info .title")).to_contain_text(
        "IDeepRL study platform", timeout=60_000
    )
    expect(page.locator(".opblock-summary-path", has_text="/api/studies").first).to_be_visible(
        timeout=30_000
    )
    scripts = page.evaluate("[...document.scripts].map(s => s.src).filter(Boolean)")
    assert scripts and all(urlsplit(s).hostname in LOOPBACK for s in scripts), scripts
    context.close()
