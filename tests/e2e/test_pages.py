"""The pages' routing and texts, and the dashboard's door, over plain HTTP."""

from __future__ import annotations

import re

import httpx
import pytest

from tests.e2e.conftest import Live
from tests.server.live import API_KEY

pytestmark = pytest.mark.slow


def _get(live: Live, path: str) -> httpx.Response:
    with httpx.Client(base_url=live.url, timeout=60) as client:
        return client.get(path)


def _consent(live: Live, token: str, decision: str = "agree") -> httpx.Response:
    """The consent form as the page posts it, with the texts version it showed."""
    page = _get(live, f"/p/{token}/consent").text
    version = re.search(r'name="texts_version" value="(\d+)"', page)
    assert version is not None, "the consent page carries its texts version"
    with httpx.Client(base_url=live.url, timeout=60) as client:
        return client.post(
            f"/p/{token}/consent", data={"decision": decision, "texts_version": version[1]}
        )


def test_a_link_leads_to_consent_then_induction_before_the_start(live: Live) -> None:
    session = live.human_session("pages", advice_budget=7)
    token = session["participant_token"]
    entry = _get(live, f"/p/{token}")
    assert entry.status_code == 303 and entry.headers["location"] == f"/p/{token}/consent"
    for path in ("advise", "thanks", "induction/1", "induction/3"):
        assert _get(live, f"/p/{token}/{path}").headers["location"] == f"/p/{token}/consent"
    consent = _get(live, f"/p/{token}/consent")
    assert consent.status_code == 200 and "7 times" in consent.text
    agreed = _consent(live, token)
    assert agreed.status_code == 303 and agreed.headers["location"] == f"/p/{token}/induction/1"
    assert _get(live, f"/p/{token}/consent").headers["location"] == f"/p/{token}/induction/1"
    assert _get(live, f"/p/{token}/advise").headers["location"] == f"/p/{token}/induction/1"
    assert _get(live, f"/p/{token}/induction/9").headers["location"].endswith("/induction/1")
    third = _get(live, f"/p/{token}/induction/3")
    assert 'id="start"' in third.text and "Choices left: 7" in third.text


def test_unknown_links_get_an_error_page(live: Live) -> None:
    for path in ("/p/nope", "/p/nope/consent", "/p/nope/induction/1", "/p/nope/advise"):
        response = _get(live, path)
        assert response.status_code == 403, path
        assert "This link is not valid" in response.text and "researcher" in response.text


def test_a_study_sets_its_own_texts_and_sorting_rule(live: Live) -> None:
    texts = {
        "title": "Robot <helper>",
        "consent": "## Hello\nYou give **{advice_budget}** pieces of advice.\n\n- one\n- two",
        "induction_2": "Rule: {sorting_rule}.",
    }
    with live.api() as api:
        study = api.post("/api/studies", json={"name": "own texts", "texts": texts}).json()
    session = live.human_session("own texts", sort_rule="shape", advice_budget=4)
    token = session["participant_token"]
    consent = _get(live, f"/p/{token}/consent").text
    assert "<title>Before you begin · Robot &lt;helper&gt;</title>" in consent
    assert "<h2>Hello</h2>" in consent and "<strong>4</strong>" in consent
    assert "<ul><li>one</li><li>two</li></ul>" in consent
    _consent(live, token)
    second = _get(live, f"/p/{token}/induction/2").text
    rule = "put the cylinders and disks on the right table and the cubes on the left table"
    assert rule in second
    assert "The robot and the experiment" in _get(live, f"/p/{token}/induction/1").text
    assert study["texts"] == texts


def test_the_dashboard_needs_the_key_and_keeps_it_out_of_urls(live: Live) -> None:
    with httpx.Client(base_url=live.url, timeout=60) as client:
        assert client.get("/dashboard").headers["location"] == "/dashboard/login"
        assert client.get("/dashboard/api/overview").status_code == 401
        wrong = client.post("/dashboard/login", data={"key": "guess"})
        assert wrong.status_code == 401 and "not the researcher key" in wrong.text
        right = client.post("/dashboard/login", data={"key": API_KEY})
        assert right.status_code == 303 and API_KEY not in right.headers["location"]
        cookie = right.headers["set-cookie"]
        assert re.search(r"(?i)httponly", cookie) and re.search(r"(?i)samesite=strict", cookie)
        assert API_KEY not in cookie
        assert client.get("/dashboard").status_code == 200
        assert client.get("/dashboard/api/overview").status_code == 200
        refused = client.post("/dashboard/api/studies", json={"name": "no header"})
        assert refused.status_code == 403 and "X-Requested-With" in refused.json()["detail"]
        headers = {"X-Requested-With": "test"}
        made = client.post("/dashboard/api/studies", json={"name": "by header"}, headers=headers)
        assert made.status_code == 201
        bad = client.post(
            f"/dashboard/api/studies/{made.json()['id']}/participants",
            json={"participant": "no spaces"},
            headers=headers,
        )
        assert bad.status_code == 422 and "pseudonym" in bad.json()["detail"]
        client.post("/dashboard/logout")
        assert client.get("/dashboard/api/overview").status_code == 401
