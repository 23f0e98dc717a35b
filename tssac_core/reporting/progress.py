"""Progress bars of long work: tqdm bars on stderr with the console's log lines printed above them, and the bars of
missions flown in the batched world, whose time left is :mod:`tssac_core.sim.time_left`'s estimate (one batch, or
the largest of the shards flown at once), not tqdm's rate of finished missions."""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from typing import Any

from tssac_core.sim.time_left import ShardProgress, TimeLeft


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
        self._shown = 0.0

    def step(self, flying: int, still_flying: int) -> None:
        self.left.tick(flying, still_flying)
        now = self.left.clock_s
        if flying != still_flying:
            self.bar.update(flying - still_flying)
        if now - self._shown >= 0.5 or still_flying == 0:
            self._shown = now
            show_time_left(self.bar, self.left.seconds)

    def __enter__(self) -> MissionBar:
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.close()


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
