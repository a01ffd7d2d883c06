"""Dashboard logins expire and logout ends them on the server: a copied cookie is
refused after logout or after its time, and is `Secure` when the site is served over
HTTPS (here: a proxy's X-Forwarded-Proto, as uvicorn trusts from the local host)."""

from __future__ import annotations

import time
from collections.abc import Iterator

import httpx
import pytest

from server.routes.dashboard import COOKIE
from tests.server.live import API_KEY, LiveServer, serving

pytestmark = pytest.mark.live

LIFETIME_S = 3


@pytest.fixture(scope="module")
def short_logins(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    data_dir = tmp_path_factory.mktemp("logins")
    with serving(data_dir, dashboard_login_s=LIFETIME_S) as live:
        yield live


def _login(server: LiveServer, **headers: str) -> httpx.Response:
    with httpx.Client(base_url=server.url, timeout=30) as browser:
        return browser.post("/dashboard/login", data={"key": API_KEY}, headers=headers)


def _overview(server: LiveServer, cookie: str) -> int:
    with httpx.Client(base_url=server.url, timeout=30, cookies={COOKIE: cookie}) as copied:
        return copied.get("/dashboard/api/overview").status_code


def test_the_servers_address_alone_leads_to_the_dashboards_login(server: LiveServer) -> None:
    with httpx.Client(base_url=server.url, timeout=30, follow_redirects=True) as browser:
        landing = browser.get("/")
    assert [r.headers["location"] for r in landing.history] == ["/dashboard", "/dashboard/login"]
    assert landing.status_code == 200 and 'name="key"' in landing.text


def test_the_cookie_is_refused_after_logout(server: LiveServer) -> None:
    first = _login(server).cookies[COOKIE]
    second = _login(server).cookies[COOKIE]
    assert first != second and API_KEY not in first
    assert _overview(server, first) == 200 and _overview(server, second) == 200
    with httpx.Client(base_url=server.url, timeout=30, cookies={COOKIE: first}) as browser:
        assert browser.post("/dashboard/logout").status_code == 303
    assert _overview(server, first) == 401, "logout ends the login on the server"
    assert _overview(server, second) == 200, "another login is unaffected"
    assert _overview(server, "forged") == 401


def test_logins_expire(short_logins: LiveServer) -> None:
    response = _login(short_logins)
    cookie = response.cookies[COOKIE]
    assert f"Max-Age={LIFETIME_S}" in response.headers["set-cookie"]
    assert _overview(short_logins, cookie) == 200
    time.sleep(LIFETIME_S + 1)
    assert _overview(short_logins, cookie) == 401


def test_the_cookie_is_secure_behind_https(server: LiveServer) -> None:
    plain = _login(server).headers["set-cookie"].lower()
    proxied = _login(server, **{"X-Forwarded-Proto": "https"}).headers["set-cookie"].lower()
    assert "secure" not in [p.strip() for p in plain.split(";")]
    assert "secure" in [p.strip() for p in proxied.split(";")]
    assert "httponly" in proxied and "samesite=strict" in proxied
