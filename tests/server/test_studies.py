import httpx


def test_study_lifecycle(api: httpx.Client) -> None:
    created = api.post("/api/studies", json={"name": "pilot", "description": "first try"})
    assert created.status_code == 201, created.text
    study = created.json()
    assert study["name"] == "pilot" and study["session_count"] == 0

    assert api.post("/api/studies", json={"name": "pilot"}).status_code == 409
    assert study["id"] in [s["id"] for s in api.get("/api/studies").json()]

    changed = api.patch(f"/api/studies/{study['id']}", json={"texts": {"consent": "Hello"}})
    assert changed.status_code == 200
    stored = api.get(f"/api/studies/{study['id']}").json()
    assert stored["texts"] == {"consent": "Hello"}
    assert stored["created_at"].endswith(("Z", "+00:00")), "timestamps say they are UTC"

    assert api.delete(f"/api/studies/{study['id']}").status_code == 204
    missing = api.get(f"/api/studies/{study['id']}")
    assert missing.status_code == 404
    assert "GET /api/studies" in missing.json()["detail"]


def test_unknown_ids_are_404_with_a_hint(api: httpx.Client) -> None:
    for path in [
        "/api/studies/999999",
        "/api/sessions/999999",
        "/api/sessions/999999/progress",
        "/api/studies/999999/sessions",
        "/api/sessions/999999/episodes",
        "/api/studies/999999/export",
    ]:
        response = api.get(path)
        assert response.status_code == 404, (path, response.text)
        assert "no " in response.json()["detail"]
