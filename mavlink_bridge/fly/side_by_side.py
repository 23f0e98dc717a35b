"""``fly --workers N`` on this machine: N crews of processes side by side, one thread of the fly process each.

Each thread owns a :class:`~mavlink_bridge.fly.mission_runner.MissionRunner` with a world and three companions of
its own (on OS-assigned ports, kept across its missions and reset between them, as in the serial run) and takes the
next mission index whenever it finishes one, so that long and short missions even out. Mission ``i`` is the same
layout and seed on any crew, so the rows are the serial run's. Nothing but the children is shared: the threads spend
their time waiting on their processes' pipes, and the processes do the work on the machine's cores.

Ray is not needed for this; it costs a few seconds of start-up and its own daemons' CPU beside the crews
(``--executor ray`` or ``--address`` fly on Ray instead: :mod:`mavlink_bridge.fly.workers`).

The main thread hands each finished row to the caller. A failure in a crew (a child that crashed, a world that did
not reset) or in the caller's handling of a row (a mission timeout) stops every crew and is raised in the main
thread; so is Ctrl-C or SIGTERM, which Python delivers to the main thread while it waits for rows.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from mavlink_bridge.fly.config import FlyConfig
from mavlink_bridge.fly.mission_row import MissionRow
from mavlink_bridge.fly.mission_runner import MissionRunner
from mavlink_bridge.processes.children import ChildProcesses

_log = logging.getLogger("mavlink_bridge.fly")

WAIT_S = 0.5
"""How long the main thread waits for a row at a time (a signal interrupts the wait at once anyway)."""


class _Indices:
    """The mission indices still to fly, handed out one at a time to the crews' threads: a cursor over the range, so
    that the memory does not grow with ``--episodes`` (a queue of every index ran out of memory at 10^8 missions
    before the first one flew)."""

    def __init__(self, indices: Sequence[int]) -> None:
        self._indices = iter(indices)
        self._lock = threading.Lock()

    def take(self) -> int | None:
        """The next index, or None when every one has been handed out."""
        with self._lock:
            return next(self._indices, None)


@dataclass
class _Done:
    """A crew's thread has ended: its missions are flown, or it stopped (``error``: why, raised in the main thread)."""

    error: BaseException | None = None


@dataclass
class _Crew:
    """One thread, its runner and the processes it started."""

    runner: MissionRunner
    children: ChildProcesses
    thread: threading.Thread = field(init=False)


def fly_side_by_side(cfg: FlyConfig, workers: int, work_dir: Path, on_row: Callable[[MissionRow], None]) -> None:
    """Fly the missions of ``cfg.indices()`` with ``workers`` crews at once; ``on_row`` gets each row in the main
    thread as its mission ends (so an interruption keeps the finished ones). Raises what stopped a crew."""
    todo = _Indices(cfg.indices())
    results: queue.SimpleQueue[MissionRow | _Done] = queue.SimpleQueue()
    stop = threading.Event()
    # With fresh processes per mission the runner's CPU figure is the reaped children's: every crew's at once here.
    crews = [
        _Crew(MissionRunner(cfg, children, work_dir, children_cpu=False), children)
        for children in (ChildProcesses() for _ in range(min(workers, len(cfg.indices()))))
    ]
    for n, crew in enumerate(crews):
        crew.thread = threading.Thread(
            target=_fly_crew, args=(crew, todo, results, stop), name=f"fly-crew-{n}", daemon=True
        )
        crew.thread.start()
    try:
        running = len(crews)
        while running:
            try:
                item = results.get(timeout=WAIT_S)
            except queue.Empty:
                continue
            if isinstance(item, _Done):
                running -= 1
                if item.error is not None:
                    raise item.error
            else:
                on_row(item)
    finally:
        stop.set()
        for crew in crews:  # a crew in a mission stops at once: its runner sees its processes end
            crew.children.stop_all()
        for crew in crews:
            crew.thread.join()


def _fly_crew(
    crew: _Crew, todo: _Indices, results: queue.SimpleQueue[MissionRow | _Done], stop: threading.Event
) -> None:
    """One crew's thread: the next mission while there is one and nothing has stopped the run."""
    error: BaseException | None = None
    try:
        while not stop.is_set():
            index = todo.take()
            if index is None:
                break
            row = crew.runner.fly(index)
            crew.children.forget_finished()
            if not stop.is_set():
                results.put(row)
    except BaseException as exc:  # handed to the main thread, which stops the other crews
        if not stop.is_set():
            error = exc
        else:
            _log.debug("%s stopped: %s", threading.current_thread().name, exc)
    finally:
        # This thread's own children go with it (the parent-death signal follows the thread that started them).
        try:
            crew.runner.close()
        finally:
            crew.children.stop_all()
            results.put(_Done(error))
