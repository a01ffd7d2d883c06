"""The task's bookkeeping for events the fast mode never produces (objects lost)."""

import sim
from sim.rules import SortRule
from sim.task import SortingTask, StepEvents


def new_task() -> SortingTask:
    kinds = {f"objects/{s}_{c}": (s, c) for s in sim.SHAPES for c in sim.COLORS}
    task = SortingTask(SortRule.parse("color"), kinds)
    task.reset()
    return task


def test_losing_the_last_object_ends_the_episode_as_a_success() -> None:
    task = new_task()
    for name in list(task.remaining)[:5]:
        _shape, color = task.kinds[name]
        assert task.update(StepEvents(grabbed=name)) == (0.0, False)
        side = "right" if color == "blue" else "left"
        task.update(StepEvents(placed=(name, side)))
    last = task.remaining[0]
    reward, terminated = task.update(StepEvents(lost=(last,)))
    assert (reward, terminated, task.succeeded, task.lost) == (0.0, True, True, 1)
    assert task.info()["remaining"] == [] and task.info()["placed_correct"] == 5


def test_an_object_lost_while_another_is_held_does_not_complete_the_task() -> None:
    task = new_task()
    held, other = task.remaining[0], task.remaining[1]
    task.update(StepEvents(grabbed=held))
    for name in task.remaining[1:]:
        task.update(StepEvents(lost=(name,)))
    assert task.remaining == [other] and not task.succeeded
    reward, terminated = task.update(StepEvents(lost=(other,)))
    assert (reward, terminated) == (0.0, False)  # still holding one
    reward, terminated = task.update(
        StepEvents(placed=(held, "left" if "red" in held else "right"))
    )
    assert (reward, terminated, task.succeeded, task.lost) == (1.0, True, True, 5)
