"""Time left for missions flown at once in the batched world.

Missions flown side by side end in bursts: none for a long while, then hundreds within a few steps, then a tail
of long ones flown almost alone. A bar that takes its rate from finished missions swings from "?" to far too
short (it said 11 s with about 3 minutes to go). The batched world, the observations and the pilots' forward passes
work on every mission's row at every step, flying or finished, so a step costs about the same from the second step to
the last (1,000 missions of random.yaml: 14 ms of CPU per step, within 6-20 ms in every window of 100 steps). The
first step is not like the others: it builds every layout's route fields (about 35 ms per layout) and is left out;
and the steps between two decisions cost far less than a decision's, so the mean waits for :data:`MIN_TIMED_STEPS`
steps (several decisions). So the estimate here is

    time left = (cap - steps so far) * (mean time of a step after the first)

which is exact when a mission runs to the episode cap (of hundreds of missions, a few do) and shrinks to 0 when the
last one ends. Missions flown in shards on several workers (``evaluate --workers N``) each report their shard's
estimate; the shards fly at once, so what is left is the largest of them (:class:`ShardsBar`).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from typing import Any

MIN_TIMED_STEPS = 50
"""Steps after the first that are timed before there is an estimate (five decisions at the usual 10 steps)."""


@dataclass
class TimeLeft:
    """The time-left estimate of the module docstring for ``missions`` missions of at most ``cap`` steps."""

    missions: int
    cap: int
    steps: int = 0
    running: int = -1
    timed_s: float = 0.0
    """Wall time of the steps after the first."""

    def __post_init__(self) -> None:
        if self.running < 0:
            self.running = self.missions

    def step(self, flying: int, still_flying: int, dt_s: float) -> None:
        """One step of the batch took ``dt_s``: ``flying`` missions flew it, ``still_flying`` fly on."""
        if self.steps > 0:
            self.timed_s += dt_s
        self.steps += 1
        self.running = still_flying

    @property
    def seconds(self) -> float | None:
        """The estimate; None before :data:`MIN_TIMED_STEPS` steps after the first have been timed."""
        if self.running == 0:
            return 0.0
        if self.steps <= MIN_TIMED_STEPS:
            return None
        return max(0, self.cap - self.steps) * self.timed_s / (self.steps - 1)


@contextmanager
def progress_bar(**tqdm_args: Any) -> Iterator[Any]:
    """A tqdm bar on stderr (``tqdm_args``: tqdm's) for the length of the block, with the console's log lines printed
    above it rather than after it on its line (tqdm's ``logging_redirect_tqdm``)."""
    from tqdm import tqdm
    from tqdm.contrib.logging import logging_redirect_tqdm

    with logging_redirect_tqdm(), tqdm(file=sys.stderr, **tqdm_args) as bar:
        yield bar


class MissionBar:
    """A tqdm bar of finished missions whose time left is :class:`TimeLeft`'s, not tqdm's rate of missions;
    ``step`` is ``fly_missions``' ``on_step``. Log lines print above it (:func:`progress_bar`)."""

    def __init__(self, missions: int, cap: int, disable: bool = False) -> None:
        self.left = TimeLeft(missions, cap)
        self._stack = ExitStack()
        self.bar = self._stack.enter_context(mission_bar(missions, disable))
        self._last = time.perf_counter()
        self._shown = 0.0

    def step(self, flying: int, still_flying: int) -> None:
        now = time.perf_counter()
        self.left.step(flying, still_flying, now - self._last)
        self._last = now
        if flying != still_flying:
            self.bar.update(flying - still_flying)
        if now - self._shown >= 0.5 or still_flying == 0:
            self._shown = now
            show_time_left(self.bar, self.left.seconds)

    def __enter__(self) -> MissionBar:
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.close()


@dataclass(frozen=True)
class ShardProgress:
    """What a shard of missions flown on a worker reports: the missions it finished since its last report, and its
    own time left then (None: not known yet)."""

    shard: int
    finished: int
    seconds_left: float | None


class ShardsBar:
    """A tqdm bar of the missions of ``shards`` shards flown at once; ``update`` is the driver's handler of their
    :class:`ShardProgress` reports. Time left: the largest of the shards' latest estimates, each less the time since
    it came; unknown while a shard has not said."""

    def __init__(self, missions: int, shards: int, disable: bool = False) -> None:
        self.shards = shards
        self._reports: dict[int, tuple[float | None, float]] = {}
        self._stack = ExitStack()
        self.bar = self._stack.enter_context(mission_bar(missions, disable))

    def update(self, report: ShardProgress) -> None:
        now = time.perf_counter()
        self._reports[report.shard] = (report.seconds_left, now)
        if report.finished:
            self.bar.update(report.finished)
        show_time_left(self.bar, self.seconds(now))

    def seconds(self, now: float) -> float | None:
        if len(self._reports) < self.shards or any(left is None for left, _ in self._reports.values()):
            return None
        return max(max(0.0, left - (now - at)) for left, at in self._reports.values() if left is not None)

    def __enter__(self) -> ShardsBar:
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.close()


def mission_bar(missions: int, disable: bool) -> Any:
    """The bar of finished missions with the time left as its postfix (a context manager)."""
    return progress_bar(
        total=missions,
        desc="missions",
        unit="mission",
        disable=disable,
        bar_format="{desc}: {n_fmt}/{total_fmt} |{bar}| [{elapsed}, {postfix}]",
        postfix="time left ?",
    )


def show_time_left(bar: Any, seconds: float | None) -> None:
    bar.set_postfix_str("time left ?" if seconds is None else f"about {format_seconds(seconds)} left", refresh=False)
    bar.refresh()


def format_seconds(seconds: float) -> str:
    """``12 s``, ``3:05`` or ``1:02:03``."""
    s = int(round(seconds))
    if s < 60:
        return f"{s} s"
    h, rest = divmod(s, 3600)
    m, sec = divmod(rest, 60)
    return f"{h}:{m:02d}:{sec:02d}" if h else f"{m}:{sec:02d}"
