"""Apply a function (or a generator function) to a list of items as Ray tasks, a few at a time, in the items' order.

The engine under ``evaluate --workers N`` (one task per shard of missions) and ``fly --workers N`` (one
task per SITL mission). ``fn(item)`` returns the item's result (``on_result(index, result)`` as it comes,
and, in the items' order, the return value), or is a generator whose return value is the result and whose
yields are progress (``on_event(x)`` in the driver, as they come). Each task is a Ray generator task asking
for one CPU: Ray streams its yields to the driver, which waits on the tasks themselves (no actor carries the
progress and no one is polled).

- At most ``workers`` tasks are in flight.
- A task whose worker process dies (killed, out of memory, its node lost) is submitted again by the driver
  (:data:`WORKER_RETRIES` times), not by Ray: Ray would drop as many of a retried generator's yields as the
  dead one had delivered, and a retry that reports its progress less often could lose its result that way.
  A retried task reports its progress again.
- The first task that raises cancels the others and raises :class:`TaskFailed` (one line naming the item).
- KeyboardInterrupt (Ctrl-C) cancels every task (each gets a KeyboardInterrupt, to stop what it started) and
  is re-raised.
- A task that has already ended is never cancelled: a cancellation that meets Ray's own completion of the task
  aborts the driver in Ray 2.52 ("Tried to complete task that was not pending", the race of ray-project/ray#54846).
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from dataclasses import dataclass
from typing import Any, Generic, Protocol, TypeVar

from tssac_core.parallel.ray_cluster import RayTarget, ray_session

T = TypeVar("T")
R = TypeVar("R")
T_co = TypeVar("T_co", covariant=True)


class Items(Protocol[T_co]):
    """What :func:`map_on_ray` reads of its items: their number and each by its index, when it is submitted (a list,
    or a view that makes each item on demand, so that a million missions cost no memory before they fly)."""

    def __len__(self) -> int: ...

    def __getitem__(self, index: int, /) -> T_co: ...


WORKER_RETRIES = 3
"""Times the driver submits an item again after its worker process died."""
DRIVER_WAKE_S = 1.0
"""The longest the driver waits on its tasks in one call (so that Ctrl-C is seen at once)."""
CANCEL_GRACE_S = 15.0
"""How long cancelled tasks get to clean up (stop their processes) before they are killed."""


class TaskFailed(Exception):
    """A task raised, or its worker died more often than it is submitted again; ``str()`` is one line."""

    def __init__(self, index: int, message: str) -> None:
        super().__init__(message)
        self.index = index


class TaskError(Exception):
    """What :func:`next_yield` raises: ``str()`` is one line; ``worker_died``: the task's worker process died (killed,
    out of memory, its node lost), so running it again may succeed; otherwise the task raised (it would again)."""

    def __init__(self, message: str, worker_died: bool) -> None:
        super().__init__(message)
        self.worker_died = worker_died


def next_yield(ray: Any, generator: Any) -> Any:
    """The next value a Ray generator task (``generator``, its ObjectRefGenerator, ready) yielded; :class:`TaskError`
    if it raised, if its worker died, or if it ended: every task here ends with a last report the caller reads
    before asking again, so an end before it means the task stopped early."""
    try:
        return ray.get(next(generator))
    except StopIteration:
        raise TaskError("its Ray task ended before its last report", worker_died=False) from None
    except ray.exceptions.RayTaskError as exc:  # RayTaskError first: it is a RayError too
        raise TaskError(one_line(exc), worker_died=False) from None
    except ray.exceptions.RayError as exc:
        raise TaskError(one_line(exc), worker_died=True) from None


@dataclass(frozen=True)
class Finished(Generic[R]):
    """A task's last yield: what its function returned."""

    value: R


def stream(fn: Callable[[T], R | Generator[Any, None, R]], item: T) -> Generator[Any, None, None]:
    """The Ray task: ``fn(item)``'s yields if it is a generator, then its result as :class:`Finished`."""
    out = fn(item)
    result = (yield from out) if isinstance(out, Generator) else out
    yield Finished(result)


def map_on_ray(
    fn: Callable[[T], R | Generator[Any, None, R]],
    items: Items[T],
    workers: int,
    target: RayTarget,
    on_result: Callable[[int, R], None] = lambda index, result: None,
    on_event: Callable[[Any], None] = lambda event: None,
    collect: bool = True,
) -> list[R]:
    """The return values of ``fn(item)`` for every item, run as Ray tasks, at most ``workers`` at once
    (module docstring); ``collect`` False: only ``on_result`` gets them (the return value is empty), and the memory
    used does not grow with the number of items."""
    results: dict[int, R] = {}
    if not len(items):
        return []
    with ray_session(target) as ray:
        task = ray.remote(num_cpus=1, max_retries=0)(stream)
        next_index = 0
        """The first item not submitted yet (one whose worker died is submitted again at once)."""
        running: dict[int, tuple[Any, int]] = {}
        """id(task's ObjectRefGenerator) -> (it, its item's index)."""
        attempts: dict[int, int] = {}
        """Submissions of each running item (forgotten when it finishes)."""

        def submit(index: int) -> None:
            attempts[index] = attempts.get(index, 0) + 1
            generator = task.remote(fn, items[index])
            running[id(generator)] = (generator, index)

        try:
            while next_index < len(items) or running:
                while next_index < len(items) and len(running) < workers:
                    submit(next_index)
                    next_index += 1
                ready, _ = ray.wait([g for g, _ in running.values()], num_returns=1, timeout=DRIVER_WAKE_S)
                for generator in ready:
                    index = running[id(generator)][1]
                    try:
                        value = next_yield(ray, generator)
                    except TaskError as exc:
                        if not exc.worker_died or attempts[index] > WORKER_RETRIES:
                            # Its task has ended: cancelling it would race Ray's completion of it (`cancel`).
                            del running[id(generator)]
                            raise TaskFailed(index, str(exc)) from None
                        del running[id(generator)]
                        submit(index)
                        continue
                    if isinstance(value, Finished):
                        del running[id(generator)]
                        del attempts[index]
                        if collect:
                            results[index] = value.value
                        on_result(index, value.value)
                    else:
                        on_event(value)
        finally:
            if running:
                cancel(ray, [g for g, _ in running.values()])
    return [results[i] for i in range(len(items))] if collect else []


def cancel(ray: Any, refs: list[Any]) -> None:
    """Cancel tasks (a KeyboardInterrupt in each), wait for them to clean up, then kill those still running.

    ``refs``: tasks' ObjectRefs or generator tasks' ObjectRefGenerators; a generator is waited for by its
    ``completed()`` ref, since it reads as ready as soon as it is cancelled, before its task has cleaned up."""
    ends = {(r.completed() if isinstance(r, ray.ObjectRefGenerator) else r): r for r in refs}
    # Not those that have ended (module docstring).
    ended, _ = ray.wait(list(ends), num_returns=len(ends), timeout=0)
    for end, ref in ends.items():
        if end not in ended:
            ray.cancel(ref)
    _, late = ray.wait(list(ends), num_returns=len(ends), timeout=CANCEL_GRACE_S)
    for end in late:
        ray.cancel(ends[end], force=True)


def one_line(exc: BaseException) -> str:
    """The last line of a Ray error's cause, without the traceback Ray wraps around it."""
    cause = getattr(exc, "cause", None)
    lines = str(cause if cause is not None else exc).strip().splitlines()
    return lines[-1] if lines else type(exc).__name__
