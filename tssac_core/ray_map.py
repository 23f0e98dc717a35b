"""Apply a function to a list of items as Ray tasks, a few at a time, keeping the items' order.

The engine under ``evaluate --workers N`` (one task per shard of missions) and ``fly --workers N`` (one
task per SITL mission): at most ``workers`` tasks are in flight, each asking for one CPU; a task whose
worker dies is run again by Ray; results reach the caller as they come (``on_result``) and, in the
items' order, as the return value. A task can report progress through the queue it is given as its
last argument (``events.put(x)``; ``on_event(x)`` in the driver). The first task that raises cancels
the others and raises :class:`TaskFailed`; KeyboardInterrupt (Ctrl-C) cancels every task (each gets a
KeyboardInterrupt, to stop what it started) and is re-raised.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from tssac_core.ray_cluster import RayTarget, ray_session

T = TypeVar("T")
R = TypeVar("R")

WORKER_RETRIES = 3
"""Times Ray runs an item again after its worker process died."""
POLL_S = 0.2
CANCEL_GRACE_S = 15.0
"""How long cancelled tasks get to clean up (stop their processes) before they are killed."""


class TaskFailed(Exception):
    """A task raised; ``str()`` is one line naming the item."""

    def __init__(self, index: int, message: str) -> None:
        super().__init__(message)
        self.index = index


def map_on_ray(
    fn: Callable[..., R],
    items: Sequence[T],
    workers: int,
    target: RayTarget,
    on_result: Callable[[int, R], None] = lambda index, result: None,
    on_event: Callable[[Any], None] = lambda event: None,
) -> list[R]:
    """``[fn(item, events) for item in items]`` over Ray workers, at most ``workers`` at once (module docstring)."""
    results: dict[int, R] = {}
    if not items:
        return []
    with ray_session(target) as ray:
        from ray.util.queue import Queue

        events = Queue(actor_options={"num_cpus": 0})
        task = ray.remote(num_cpus=1, max_retries=WORKER_RETRIES, retry_exceptions=False)(fn)
        todo = list(enumerate(items))
        running: dict[Any, int] = {}
        try:
            while todo or running:
                while todo and len(running) < workers:
                    index, item = todo.pop(0)
                    running[task.remote(item, events)] = index
                done, _ = ray.wait(list(running), num_returns=1, timeout=POLL_S)
                drain(events, on_event)
                for ref in done:
                    index = running.pop(ref)
                    try:
                        results[index] = ray.get(ref)
                    except Exception as exc:  # the task raised, or its worker died more often than it is retried
                        raise TaskFailed(index, one_line(exc)) from None
                    on_result(index, results[index])
        finally:
            if running:
                cancel(ray, list(running))
            drain(events, on_event)
    return [results[i] for i in range(len(items))]


def drain(events: Any, on_event: Callable[[Any], None]) -> None:
    """Hand the driver the events the tasks put since the last call."""
    count = events.size()
    for event in events.get_nowait_batch(count) if count else []:
        on_event(event)


def cancel(ray: Any, refs: list[Any]) -> None:
    """Cancel tasks (a KeyboardInterrupt in each), wait for them to clean up, then kill those still running.

    ``refs``: tasks' ObjectRefs or generator tasks' ObjectRefGenerators; a generator is waited for by its
    ``completed()`` ref, since it reads as ready as soon as it is cancelled, before its task has cleaned up."""
    for ref in refs:
        ray.cancel(ref)
    ends = {(r.completed() if isinstance(r, ray.ObjectRefGenerator) else r): r for r in refs}
    _, late = ray.wait(list(ends), num_returns=len(ends), timeout=CANCEL_GRACE_S)
    for end in late:
        ray.cancel(ends[end], force=True)


def one_line(exc: BaseException) -> str:
    """The last line of a Ray error's cause, without the traceback Ray wraps around it."""
    cause = getattr(exc, "cause", None)
    lines = str(cause if cause is not None else exc).strip().splitlines()
    return lines[-1] if lines else type(exc).__name__
