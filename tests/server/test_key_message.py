"""Where the researcher key is, said alike by `ideeprl serve` and the dashboard's login:
with the server's output going to a file (here, as in a service's journal) the banner
says where the key is, never the key, and the login page says that is what it does."""

from __future__ import annotations

import re

import httpx

from tests.server.live import API_KEY, LiveServer


def _text(html: str) -> str:
    return " ".join(re.sub(r"<[^>]+>", " ", html).split())


def test_the_login_page_says_what_serve_printed_into_its_file(server: LiveServer) -> None:
    [line] = [x for x in server.log.read_text().splitlines() if "researcher key:" in x]
    assert API_KEY not in line, line
    assert "IDEEPRL_API_KEY" in line, "the key comes from the environment here"
    page = _text(httpx.get(f"{server.url}/dashboard/login", timeout=30).text)
    assert "at a terminal" in page, page
    assert "output going to a file" in page and "says where the key is" in page, page
    assert "api_key" in page and "IDEEPRL_API_KEY" in page, page
