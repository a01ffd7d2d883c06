import asyncio

from server.live.hub import Hub, HubEvent


def test_subscribers_get_their_session_only_and_late_ones_get_the_scene_first() -> None:
    hub = Hub()
    watched: list[tuple[int, bool]] = []
    hub.on_watchers_changed(lambda sid, on: watched.append((sid, on)))
    hub.publish(1, "scene_reset", {"bodies": ["table"]})
    hub.publish(1, "scene_step", {"poses": 1})
    hub.publish(2, "scene_reset", {"bodies": ["other"]})

    got: list[HubEvent] = []
    subscription = hub.subscribe(1, got.append)
    assert [e.kind for e in got] == ["scene_reset", "scene_step"]
    assert got[0].payload == {"bodies": ["table"]}
    hub.publish(1, "progress", {"episode": 3})
    hub.publish(2, "progress", {"episode": 9})
    assert [e.payload for e in got[2:]] == [{"episode": 3}]
    subscription.close()
    hub.publish(1, "progress", {"episode": 4})
    assert len(got) == 3
    assert watched == [(1, True), (1, False)]


def test_a_new_scene_replaces_the_last_step_in_the_replay() -> None:
    hub = Hub()
    hub.publish(1, "scene_step", {"poses": "old"})
    hub.publish(1, "scene_reset", {"bodies": []})
    got: list[HubEvent] = []
    hub.subscribe(1, got.append, kinds=["scene_reset", "scene_step"])
    assert [e.kind for e in got] == ["scene_reset"]


def test_a_failing_subscriber_does_not_stop_the_others() -> None:
    hub = Hub()
    got: list[HubEvent] = []

    def broken(_: HubEvent) -> None:
        raise RuntimeError("viewer bug")

    hub.subscribe(5, broken)
    hub.subscribe(5, got.append)
    hub.publish(5, "episode", {"collected_reward": 1.0})
    assert len(got) == 1


def test_stream_yields_events_published_from_another_thread() -> None:
    hub = Hub()

    async def main() -> list[str]:
        stream = hub.stream(7, kinds=["episode"])
        loop = asyncio.get_running_loop()
        first = asyncio.ensure_future(anext(stream))
        await asyncio.sleep(0.01)
        await loop.run_in_executor(None, hub.publish, 7, "episode", {"n": 1})
        event = await asyncio.wait_for(first, 5)
        await stream.aclose()
        return [event.kind, event.payload["n"]]

    assert asyncio.run(main()) == ["episode", 1]
