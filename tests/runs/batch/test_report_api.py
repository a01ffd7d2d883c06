"""The researcher's report endpoint on a live server, over the batch's study."""

from __future__ import annotations

import io
import zipfile
from collections.abc import Iterator

import httpx
import pytest

from tests.runs.batch.helpers import Place, sessions, study_id, training_totals
from tests.server.live import LiveServer

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def api(place: Place, baselines: str) -> Iterator[httpx.Client]:
    """The server writes its reports' figures in every format, as a researcher's does (the
    tests' environment asks for PNGs alone, tests/conftest.py)."""
    server = LiveServer(place.data_dir, place.url, figure_formats="png,svg,pdf").start()
    try:
        with server.client() as client:
            yield client
    finally:
        server.stop()


def test_a_researcher_builds_and_downloads_a_studys_report(place: Place, api: httpx.Client) -> None:
    engine = place.engine()
    study = study_id(engine, "baselines")
    assert api.get(f"/api/studies/{study}/report").status_code == 404  # none built yet

    built = api.post(f"/api/studies/{study}/report")
    assert built.status_code == 201, built.text
    report = built.json()
    rows = sessions(engine, study)
    advisor = next(s for s in rows if s.label.endswith("advisor"))
    runs = [s for s in rows if s.id != advisor.id]
    assert report["sessions"] == [s.id for s in runs] and report["baseline"] == "autonomous"
    totals = training_totals(engine, [s.id for s in runs])
    method_of = {s.id: s.method for s in runs}
    for method in report["methods"]:
        mine = [t for s, (_, t) in totals.items() if method_of[s] == method["method"]]
        assert method["R_T"] == pytest.approx(sum(mine) / len(mine))
    assert any(f"Left out session(s) {advisor.id}" in note for note in report["notes"])
    assert api.get(f"/api/studies/{study}/report").json()["files"] == report["files"]

    kinds = {f["kind"] for f in report["files"]}
    assert kinds == {"report", "figure", "table"}
    figures = {f["name"] for f in report["files"] if f["kind"] == "figure"}
    pngs = {name.removesuffix(".png") for name in figures if name.endswith(".png")}
    assert pngs and figures == {f"{stem}.{kind}" for stem in pngs for kind in ("png", "svg", "pdf")}
    for file in report["files"]:
        got = api.get(file["url"])
        assert got.status_code == 200, file
        if file["kind"] == "figure" and file["name"].endswith(".svg"):
            assert got.headers["content-type"] == "image/svg+xml" and b"<svg" in got.content
        elif file["kind"] == "figure" and file["name"].endswith(".pdf"):
            assert got.headers["content-type"] == "application/pdf"
            assert got.content[:5] == b"%PDF-"
        elif file["kind"] == "figure":
            assert got.headers["content-type"] == "image/png" and got.content[:4] == b"\x89PNG"
    markdown = api.get(report["report_url"]).text
    assert markdown.startswith("# baselines: the paper's analysis")

    archive = api.get(report["zip_url"])
    assert archive.status_code == 200
    names = set(zipfile.ZipFile(io.BytesIO(archive.content)).namelist())
    assert names == {f["name"] for f in report["files"]}


def test_choices_and_mistakes(place: Place, api: httpx.Client) -> None:
    study = study_id(place.engine(), "baselines")
    only_agent = api.post(f"/api/studies/{study}/report", json={"methods": ["agent"]})
    assert only_agent.status_code == 201, only_agent.text
    body = only_agent.json()
    assert body["baseline"] is None and [m["method"] for m in body["methods"]] == ["agent"]
    assert any("No autonomous DeepRL sessions" in note for note in body["notes"])
    autonomous = [
        s.id
        for s in sessions(place.engine(), study)
        if s.method == "autonomous" and not s.label.endswith("advisor")
    ]
    left_out = next(n for n in body["notes"] if "this choice left out" in n)
    assert all(str(i) in left_out for i in autonomous) and len(autonomous) == 2

    unknown = api.post(f"/api/studies/{study}/report", json={"sessions": [987654]})
    assert unknown.status_code == 404
    assert "987654 are not in study" in unknown.json()["detail"]
    bad_baseline = api.post(f"/api/studies/{study}/report", json={"baseline": "human"})
    assert bad_baseline.status_code == 422
    assert api.post("/api/studies/987654/report").status_code == 404
    assert api.get(f"/api/studies/{study}/report/files/secret.txt").status_code == 404
    assert api.get(f"/api/studies/{study}/report/files/..%2Fstudy.sqlite3").status_code in (
        404,
        422,
    )
    with httpx.Client(base_url=str(api.base_url)) as anonymous:
        assert anonymous.post(f"/api/studies/{study}/report").status_code == 401
        assert anonymous.get(f"/api/studies/{study}/report").status_code == 401
    # The last report built is the one served.
    assert api.get(f"/api/studies/{study}/report").json()["baseline"] is None
