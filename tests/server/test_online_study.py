"""An online study through its public link: the design stored whole, arrivals assigned by
seeded block randomization, the same person never given a second session, full studies
turned away with their code, early ends freeing their place, previews leaving no trace,
and deletion by panel id."""

from __future__ import annotations

import csv
import io
import json
import time
import zipfile
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import httpx
import pytest

from study.services.assignment import block_order
from tests.server.live import LiveServer
from tests.study.test_export_types import check_frictionless

TINY_RUN = {
    "method": "human",
    "config": {
        "pretraining_steps": 20,
        "advice_budget": 5,
        "batch_size": 8,
        "memory_size": 300,
        "episodes": 1,
    },
    "motion": "fast",
}


def design(target: int = 3, capacity: int = 10, **changes: Any) -> dict[str, Any]:
    return {
        "conditions": {
            "early": {"run": {**TINY_RUN, "strategy": "early"}, "target": target},
            "alternating": {
                "run": {**TINY_RUN, "strategy": "alternating"},
                "target": target,
                "texts": {"title": "Robot study B"},
            },
        },
        "capacity": capacity,
        "pool": 0,
        "panel": {"kind": "prolific", "codes": {"completed": "DONE1", "full": "FULL1"}},
        **changes,
    }


def make_study(api: httpx.Client, name: str, **design_changes: Any) -> dict[str, Any]:
    created = api.post("/api/studies", json={"name": name, "design": design(**design_changes)})
    assert created.status_code == 201, created.text
    return created.json()


def arrive(
    server: LiveServer, study: dict[str, Any], pid: str | None, address: str, **params: str
) -> httpx.Response:
    """One arrival at the study link from `address` (the test server trusts loopback's
    X-Forwarded-For, as it trusts its reverse proxy); without a panel id, through the
    link's page (its Begin button)."""
    query = {"STUDY_ID": "s1", "SESSION_ID": f"x-{pid}", **params}
    if pid is not None:
        query["PROLIFIC_PID"] = pid
    path = urlsplit(study["join_url"]).path
    with httpx.Client(base_url=server.url, headers={"X-Forwarded-For": address}) as client:
        if pid is None:
            return client.post(path, params=query)
        return client.get(path, params=query)


def token_of(response: httpx.Response) -> str:
    assert response.status_code == 303, response.text
    return response.headers["location"].removeprefix("/p/")


def sessions_of(api: httpx.Client, study: dict[str, Any]) -> list[dict[str, Any]]:
    found = api.get(f"/api/studies/{study['id']}/sessions")
    assert found.status_code == 200
    return found.json()


def test_design_is_stored_with_every_default_written_out(api: httpx.Client) -> None:
    study = make_study(api, "online-defaults")
    stored = study["design"]
    assert stored["alpha"] == 0.05 and stored["capacity"] == 10
    assert stored["panel"]["params"] == ["PROLIFIC_PID", "STUDY_ID", "SESSION_ID"]
    codes = stored["panel"]["codes"]
    assert codes["completed"] == "DONE1" and codes["full"] == "FULL1"
    assert len(set(codes.values())) == 5, "a code for each outcome, generated when not given"
    assert stored["panel"]["urls"]["completed"].startswith("https://app.prolific.com/")
    run = stored["conditions"]["early"]["run"]
    assert run["config"]["batch_size"] == 8 and "learning_rate" in run["config"]
    assert study["join_url"].startswith(api.base_url.__str__().rstrip("/") + "/join/")
    again = api.get(f"/api/studies/{study['id']}").json()
    assert again["design"] == stored, "codes are generated once, then kept"
    changed = design(capacity=4)
    del changed["panel"]["codes"]
    patched = api.patch(f"/api/studies/{study['id']}", json={"design": changed})
    assert patched.status_code == 200, patched.text
    assert patched.json()["design"]["capacity"] == 4
    assert patched.json()["design"]["panel"]["codes"] == codes, "a new design keeps the codes"
    assert patched.json()["join_url"] == study["join_url"], "and the link"


@pytest.mark.parametrize(
    "bad",
    [
        {"conditions": {}},
        {"conditions": {"a": {"run": {"method": "autonomous"}}}},
        {"conditions": {"a": {"run": {"config": {"batch_size": 0}}}}},
        {"conditions": {"a": {}}, "capacity": 0},
        {"conditions": {"a": {}}, "panel": {"kind": "custom"}},
        {"conditions": {"a": {}}, "panel": {"urls": {"completed": "javascript:alert(1)"}}},
        {"conditions": {"a": {}}, "panel": {"codes": {"completed": "a b<script>"}}},
    ],
)
def test_a_bad_design_is_a_422(api: httpx.Client, bad: dict[str, Any]) -> None:
    response = api.post("/api/studies", json={"name": "bad-design", "design": bad})
    assert response.status_code == 422, response.text


def test_arrivals_are_assigned_by_the_seeded_blocks(server: LiveServer, api: httpx.Client) -> None:
    study = make_study(api, "online-blocks", target=3)
    tokens = [token_of(arrive(server, study, f"P{i}", f"10.1.0.{i}")) for i in range(6)]
    assert len(set(tokens)) == 6
    made = sessions_of(api, study)
    got = [s["condition"] for s in sorted(made, key=lambda s: s["id"])]
    seed = assignment_seed(server, study["id"])
    expected = [c for b in range(3) for c in block_order(seed, b, ["alternating", "early"])]
    assert got == expected
    assert got.count("early") == 3 and got.count("alternating") == 3
    assert block_order(seed, 0, ["early", "alternating"]) == expected[:2], "same seed, same order"
    orders = {tuple(c for b in range(3) for c in block_order(s, b, ["a", "b"])) for s in range(20)}
    assert len(orders) > 1, "another seed, another order"

    again = arrive(server, study, "P2", "10.1.0.99")
    assert token_of(again) == tokens[2], "the same panel id gets its own session again"
    full = arrive(server, study, "P7", "10.1.0.7")
    assert full.status_code == 200 and "FULL1" in full.text
    assert "cc=FULL1" in full.text, "the full code's redirect to Prolific"
    assert len(sessions_of(api, study)) == 6

    counts = api.get(f"/api/studies/{study['id']}/conditions").json()
    assert {c["condition"]: c["in_progress"] for c in counts} == {"early": 3, "alternating": 3}


def assignment_seed(server: LiveServer, study_id: int) -> int:
    (seed,) = rows(server, "SELECT assignment_seed FROM studies WHERE id = :s", {"id": study_id})
    return int(seed)


def test_without_a_panel_id_a_cookie_tells_arrivals_apart(
    server: LiveServer, api: httpx.Client
) -> None:
    study = make_study(api, "online-cookie")
    path = urlsplit(study["join_url"]).path
    with httpx.Client(base_url=server.url, headers={"X-Forwarded-For": "10.2.0.1"}) as browser:
        # The bare link (a link preview, a crawler, someone sent it without the panel): a page
        # whose Begin button makes the session; the GET takes no place.
        for _ in range(3):
            landing = browser.get(path, params={"STUDY_ID": "S"})
            assert landing.status_code == 200 and 'id="begin"' in landing.text
            assert f'action="{path}?STUDY_ID=S"' in landing.text
            assert "<title>Help a robot learn to sort</title>" in landing.text
        assert sessions_of(api, study) == []
        first = token_of(browser.post(path))
        assert token_of(browser.get(path)) == first, "the cookie brings them back"
    with httpx.Client(base_url=server.url, headers={"X-Forwarded-For": "10.2.0.2"}) as other:
        assert token_of(other.post(path)) != first
    assert len(sessions_of(api, study)) == 2


def test_at_capacity_arrivals_see_the_full_page(server: LiveServer, api: httpx.Client) -> None:
    study = make_study(api, "online-capacity", capacity=2)
    token_of(arrive(server, study, "C1", "10.3.0.1"))
    token_of(arrive(server, study, "C2", "10.3.0.2"))
    turned = arrive(server, study, "C3", "10.3.0.3")
    assert turned.status_code == 200 and "FULL1" in turned.text
    assert "Help a robot learn to sort</title>" in turned.text, "the study's title"


def test_a_decline_ends_the_visit_and_its_place_is_refilled_first(
    server: LiveServer, api: httpx.Client
) -> None:
    study = make_study(api, "online-decline", target=1)
    first = token_of(arrive(server, study, "D1", "10.4.0.1"))
    second = token_of(arrive(server, study, "D2", "10.4.0.2"))
    assert arrive(server, study, "D3", "10.4.0.3").status_code == 200, "full: one per condition"
    with httpx.Client(base_url=server.url) as browser:
        declined = browser.post(f"/p/{first}/consent", data={"decision": "decline"})
        assert declined.status_code == 303 and declined.headers["location"] == f"/p/{first}/end"
        page = browser.get(f"/p/{first}/end")
        code = api.get(f"/api/studies/{study['id']}").json()["design"]["panel"]["codes"]
        assert code["declined"] in page.text and f"cc={code['declined']}" in page.text
        assert browser.get(f"/p/{first}").headers["location"] == f"/p/{first}/end"
    by_token = {s["participant_url"].rsplit("/", 1)[1]: s for s in sessions_of(api, study)}
    gone = by_token[first]
    with httpx.Client(base_url=server.url) as browser:  # the condition's title, over the study's
        titles = {t: browser.get(f"/p/{t}/declined").text for t in (first, second)}
    b = next(t for t in (first, second) if by_token[t]["condition"] == "alternating")
    assert [("· Robot study B</title>" in titles[t]) for t in (first, second)] == [
        t == b for t in (first, second)
    ]
    assert gone["status"] == "declined" and gone["outcome"] == "declined"
    refill = token_of(arrive(server, study, "D3", "10.4.0.3"))
    made = {s["participant_url"].rsplit("/", 1)[1]: s for s in sessions_of(api, study)}
    assert made[refill]["condition"] == gone["condition"], "the freed place goes first"
    assert made[second]["condition"] != gone["condition"]
    back = arrive(server, study, "D1", "10.4.0.1")
    assert token_of(back) == first, "after an early end: the same session, its end page"


def test_preview_takes_no_place_stays_out_of_the_export_and_deletes_in_one_call(
    server: LiveServer, api: httpx.Client, tmp_path: Path
) -> None:
    study = make_study(api, "online-preview", target=1)
    made = api.post(f"/api/studies/{study['id']}/preview")
    assert made.status_code == 201, made.text
    assert made.json()["participant_url"].startswith(server.url + "/p/")
    counts = api.get(f"/api/studies/{study['id']}/conditions").json()
    assert all(c["in_progress"] == 0 for c in counts)
    token_of(arrive(server, study, "V1", "10.5.0.1"))
    token_of(arrive(server, study, "V2", "10.5.0.2"))
    assert len(sessions_of(api, study)) == 3
    folder = exported(api, study, tmp_path / "pseudonymous")
    check_frictionless(folder)
    design = json.loads((folder / "study.json").read_text())["design"]
    assert design == api.get(f"/api/studies/{study['id']}").json()["design"], "for the analysis"
    exported_ids = {int(r["session_id"]) for r in table(folder, "sessions")}
    assert made.json()["session_id"] not in exported_ids and len(exported_ids) == 2
    assert {r["session_id"] for r in table(folder, "assignments")} == set(map(str, exported_ids))
    panel = table(folder, "panel_ids")
    assert len(panel) == 2 and not {"V1", "V2"} & {r["panel_id"] for r in panel}
    assert all(r["panel_params"] == "" for r in panel), "pseudonymous by default"
    paid = table(exported(api, study, tmp_path / "paid", panel_ids="true"), "panel_ids")
    assert {r["panel_id"] for r in paid} == {"V1", "V2"}
    from cli.main import main

    argv = ["export", "--study", str(study["id"]), "--database-url", server.database_url]
    assert (
        main([*argv, "--data-dir", str(tmp_path), "--out", str(tmp_path / "cli"), "--panel-ids"])
        == 0
    )
    assert {r["panel_id"] for r in table(tmp_path / "cli", "panel_ids")} == {"V1", "V2"}
    assert json.loads(paid[0]["panel_params"])["STUDY_ID"] == "s1"
    assert api.delete(f"/api/studies/{study['id']}/preview").status_code == 204
    assert [s["preview"] for s in sessions_of(api, study)] == [False, False]


def exported(api: httpx.Client, study: dict[str, Any], folder: Path, **params: str) -> Path:
    response = api.get(f"/api/studies/{study['id']}/export", params=params)
    assert response.status_code == 200, response.text
    zipfile.ZipFile(io.BytesIO(response.content)).extractall(folder)
    return folder


def table(folder: Path, name: str) -> list[dict[str, str]]:
    with (folder / f"{name}.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def test_deletion_by_panel_id_deletes_the_person(server: LiveServer, api: httpx.Client) -> None:
    study = make_study(api, "online-forget")
    token_of(arrive(server, study, "F1", "10.6.0.1"))
    kept = token_of(arrive(server, study, "F2", "10.6.0.2"))
    gone = api.delete(f"/api/studies/{study['id']}/panel/F1")
    assert gone.status_code == 204
    left = sessions_of(api, study)
    assert [s["participant_url"].rsplit("/", 1)[1] for s in left] == [kept]
    assert api.delete(f"/api/studies/{study['id']}/panel/F1").status_code == 404
    assert rows(server, "SELECT panel_id FROM panel_ids WHERE study_id = :s", study) == ["F2"]
    assert len(rows(server, "SELECT id FROM assignments WHERE study_id = :s", study)) == 1
    assert token_of(arrive(server, study, "F1", "10.6.0.1")) != kept
    assert api.delete(f"/api/studies/{study['id']}").status_code == 204
    for name in ("panel_ids", "assignments"):
        assert rows(server, f"SELECT id FROM {name} WHERE study_id = :s", study) == []


def rows(server: LiveServer, query: str, study: dict[str, Any]) -> list[Any]:
    from sqlalchemy import create_engine, text

    engine = create_engine(server.database_url)
    try:
        with engine.connect() as c:
            return list(c.execute(text(query), {"s": study["id"]}).scalars())
    finally:
        engine.dispose()


def test_the_link_is_rate_limited_per_address_and_per_study(
    server: LiveServer, api: httpx.Client
) -> None:
    study = make_study(api, "online-limit", capacity=10)
    answers = [arrive(server, study, None, "10.7.0.1").status_code for _ in range(31)]
    assert answers[-1] == 429 and 429 not in answers[:30], "30 a minute from one address"
    small = make_study(api, "online-limit-small", capacity=1)
    answers = [arrive(server, small, None, f"10.7.1.{i}").status_code for i in range(7)]
    assert answers[-1] == 429 and 429 not in answers[:6], "6 a minute per place"


def test_idle_past_the_limit_times_out_and_frees_the_place(
    server: LiveServer, api: httpx.Client
) -> None:
    study = make_study(api, "online-idle", target=1, idle_limit_s=1.0)
    token = token_of(arrive(server, study, "I1", "10.8.0.1"))
    with httpx.Client(base_url=server.url) as browser:
        assert browser.get(f"/p/{token}").status_code == 303  # opening it starts the worker
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:
            (session,) = [s for s in sessions_of(api, study) if token in s["participant_url"]]
            if session["outcome"] is not None:
                break
            time.sleep(0.5)
        assert session["outcome"] == "timed_out" and session["status"] == "timed_out"
        assert browser.get(f"/p/{token}").headers["location"] == f"/p/{token}/end"
    refill = token_of(arrive(server, study, "I2", "10.8.0.2"))
    made = {s["participant_url"].rsplit("/", 1)[1]: s for s in sessions_of(api, study)}
    assert made[refill]["condition"] == session["condition"]


DESIGN_FILE = """\
name: online-from-file
description: early advising against alternating
design:
  capacity: 4
  idle_limit_s: 300
  conditions:
    early:
      target: 2
      run:
        method: human
        strategy: early
        config: {pretraining_steps: 20, advice_budget: 5, batch_size: 8}
    alternating:
      target: 2
      run:
        method: human
        strategy: alternating
        config: {pretraining_steps: 20, advice_budget: 5, batch_size: 8}
      texts: {title: Robot study B}
  panel:
    kind: mturk
    codes: {completed: C1, declined: C2, excluded: C3, timed_out: C4, full: C5}
"""


def test_a_study_from_a_design_file_reads_back_as_the_file(
    server: LiveServer, api: httpx.Client, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import yaml

    from cli.main import main
    from study.schemas.design import StudyDesign
    from study.services.studies import stored_design

    source = tmp_path / "design.yaml"
    source.write_text(DESIGN_FILE)
    argv = ["study", "create", "--from", str(source), "--database-url", server.database_url]
    capsys.readouterr()
    assert main([*argv, "--data-dir", str(tmp_path), "--public-url", server.url]) == 0
    (study,) = [s for s in api.get("/api/studies").json() if s["name"] == "online-from-file"]
    assert f"its link: {study['join_url']}\n" in capsys.readouterr().out, "the server's link"

    def normalised(design: dict[str, Any]) -> dict[str, Any]:
        return stored_design(StudyDesign.model_validate(design))

    written = yaml.safe_load(DESIGN_FILE)
    assert normalised(study["design"]) == normalised(written["design"])
    assert study["design"] == normalised(written["design"]), "stored with defaults written out"
    assert study["design"]["panel"]["params"][0] == "workerId"
    assert study["description"] == written["description"] and study["join_url"]
    assert main([*argv, "--data-dir", str(tmp_path)]) == 1, "the name is taken"
    source.write_text(DESIGN_FILE.replace("capacity: 4", "capacity: 0"))
    assert main([*argv, "--data-dir", str(tmp_path), "--name", "other"]) == 2


def test_a_decline_over_the_participant_api_ends_the_visit_too(
    server: LiveServer, api: httpx.Client
) -> None:
    study = make_study(api, "online-api-decline")
    token = token_of(arrive(server, study, "A1", "10.9.0.1"))
    with server.client(key=None, token=token) as participant:
        for loose in ("yes", "true", 1, None):  # only JSON true or false is a decision
            unclear = participant.post("/api/participant/consent", json={"agree": loose})
            assert unclear.status_code == 422, (loose, unclear.text)
        declined = participant.post("/api/participant/consent", json={"agree": False})
        assert declined.status_code == 200, declined.text
        state = participant.get("/api/participant/state").json()
        assert state["status"] == "declined" and "ended" in state["message"]
        late = participant.post("/api/participant/consent", json={"agree": True})
        assert late.status_code == 409 and "visit has ended" in late.json()["detail"]
    (session,) = sessions_of(api, study)
    assert session["outcome"] == "declined" and session["status"] == "declined"
    assert session["declined_at"] and session["consented_at"] is None
    for again in ("start", "resume"):  # both say the same: the visit is over
        refused = api.post(f"/api/sessions/{session['id']}/{again}")
        assert refused.status_code == 409 and "visit has ended" in refused.json()["detail"]


def test_bad_panel_parameters_are_a_400_not_a_session(
    server: LiveServer, api: httpx.Client
) -> None:
    study = make_study(api, "online-bad-params")
    assert arrive(server, study, "x" * 201, "10.10.0.1").status_code == 400
    assert arrive(server, study, "a\x00b", "10.10.0.2").status_code == 400
    assert sessions_of(api, study) == []
    assert api.delete(f"/api/studies/{study['id']}/panel/a%00b").status_code == 422
    assert api.delete(f"/api/studies/{study['id']}/panel/{'x' * 201}").status_code == 422
    unknown = urlsplit(study["join_url"]).path[:-3] + "zzz"
    for method in ("GET", "POST"):
        page = httpx.request(method, server.url + unknown)
        assert page.status_code == 404, page.text
        assert page.headers["content-type"].startswith("text/html"), "the participant's page"
        assert "We could not find a study for this link" in page.text


def test_a_link_never_opened_times_out_and_frees_its_place(
    server: LiveServer, api: httpx.Client
) -> None:
    study = make_study(api, "online-unopened", target=1, idle_limit_s=0.5)
    first = token_of(arrive(server, study, "U1", "10.11.0.1"))  # the redirect not followed
    # Nobody else arrives: the server's own round (every 2 heartbeats) frees the place.
    deadline = time.monotonic() + 15
    while (waiting := sessions_of(api, study)[0])["status"] != "timed_out":
        assert time.monotonic() < deadline, waiting
        time.sleep(0.25)
    assert waiting["outcome"] == "timed_out" and "never opened" in waiting["status_detail"]
    second = token_of(arrive(server, study, "U2", "10.11.0.2"))
    made = {s["participant_url"].rsplit("/", 1)[1]: s for s in sessions_of(api, study)}
    assert made[first]["status"] == "timed_out" and made[first]["outcome"] == "timed_out"
    assert made[second]["condition"] == made[first]["condition"], "its place refilled"


def test_mturk_workers_return_to_mturks_own_submit_url(
    server: LiveServer, api: httpx.Client
) -> None:
    panel = {"kind": "mturk", "codes": {"declined": "NOPE"}}
    study = make_study(api, "online-mturk", panel=panel)
    path = urlsplit(study["join_url"]).path
    for worker, submit_to, expected in [
        ("W1", "https://workersandbox.mturk.com", "https://workersandbox.mturk.com"),
        ("W2", "https://evil.example", "https://www.mturk.com"),  # never an open redirect
    ]:
        query = {"workerId": worker, "assignmentId": f"A {worker}", "hitId": "H"}
        with httpx.Client(base_url=server.url, headers={"X-Forwarded-For": "10.12.0.1"}) as b:
            token = token_of(b.get(path, params={**query, "turkSubmitTo": submit_to}))
            b.post(f"/p/{token}/consent", data={"decision": "decline"})
            page = b.get(f"/p/{token}/end").text
        url = f"{expected}/mturk/externalSubmit?assignmentId=A%20{worker}&amp;code=NOPE"
        assert f'content="5;url={url}"' in page


def test_a_new_design_keeps_every_condition_that_has_participants(
    server: LiveServer, api: httpx.Client
) -> None:
    study = make_study(api, "online-redesign")
    token_of(arrive(server, study, "R1", "10.14.0.1"))
    (session,) = sessions_of(api, study)
    taken = session["condition"]
    other = ({"early", "alternating"} - {taken}).pop()
    kept_only_other = design()
    del kept_only_other["conditions"][taken]
    refused = api.patch(f"/api/studies/{study['id']}", json={"design": kept_only_other})
    assert refused.status_code == 409 and repr(taken) in refused.json()["detail"], refused.text
    unused_dropped = design()
    del unused_dropped["conditions"][other]  # nobody is in it yet: it may go
    assert api.patch(f"/api/studies/{study['id']}", json={"design": unused_dropped}).is_success
    stored = api.get(f"/api/studies/{study['id']}").json()["design"]["conditions"]
    assert set(stored) == {taken}
    for blank in ("", "   ", "\t\n"):
        assert api.patch(f"/api/studies/{study['id']}", json={"name": blank}).status_code == 422
        assert api.post("/api/studies", json={"name": blank}).status_code == 422
    renamed = api.patch(f"/api/studies/{study['id']}", json={"name": "  online-redesigned "})
    assert renamed.json()["name"] == "online-redesigned"
