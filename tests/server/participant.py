"""A simulated participant: what a browser page does, over the participant endpoints."""

from __future__ import annotations

import time
from typing import Any

import httpx

from tests.server.contract import checked_client


class SimulatedParticipant:
    def __init__(self, base_url: str, token: str) -> None:
        self.client = checked_client(
            base_url=base_url, headers={"Authorization": f"Bearer {token}"}, timeout=60
        )
        self.version: int | None = None
        self.pending: dict[str, Any] | None = None

    def consent(self, agree: bool = True) -> dict[str, Any]:
        """Read the texts and decide, as the consent page does."""
        shown = self.client.get("/api/participant/consent")
        assert shown.status_code == 200, shown.text
        version = shown.json()["texts_version"]
        response = self.client.post(
            "/api/participant/consent", json={"agree": agree, "texts_version": version}
        )
        assert response.status_code == 200, response.text
        return response.json()

    def begin(self) -> httpx.Response:
        """Consent, then the induction's Start: the session may now ask for advice."""
        self.consent()
        return self.client.post("/api/participant/start")

    def state(self) -> dict[str, Any]:
        response = self.client.get("/api/participant/state")
        assert response.status_code == 200, response.text
        data = response.json()
        self.version = data["version"]
        return data

    def next_request(self, timeout: float = 180) -> dict[str, Any]:
        """Long-poll until advice is wanted (or the session no longer runs)."""
        deadline = time.monotonic() + timeout
        state = self.pending or (
            self.state() if self.version is None else {"advice_wanted": False, "status": ""}
        )
        self.pending = None
        if state.get("version"):
            self.version = state["version"]
        while not state["advice_wanted"] and state["status"] in (
            "",
            "created",
            "running",
            "paused",
        ):
            assert time.monotonic() < deadline, f"no advice request came: {state}"
            response = self.client.get(
                "/api/participant/state", params={"after": self.version, "timeout": 10}
            )
            assert response.status_code == 200, response.text
            state = response.json()
            self.version = state["version"]
        return state

    def advise(self, advice_index: int, action: int, wait: float = 0.0) -> httpx.Response:
        """Send one advice; a stored one makes the next `next_request` wait for news (or,
        with `wait`, return the state that came with the receipt)."""
        response = self.client.post(
            "/api/participant/advice",
            params={"wait": wait},
            json={"advice_index": advice_index, "action": action},
        )
        if response.status_code == 200 and not response.json()["duplicate"]:
            receipt = response.json()
            self.version = receipt["version"]
            self.pending = receipt["state"]
        return response

    def close(self) -> None:
        self.client.close()
