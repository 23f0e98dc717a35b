"""Time left for missions flown at once in the batched world.

Missions flown side by side end in bursts: none for a long while, then hundreds within a few steps, then a tail
of long ones flown almost alone. A bar that takes its rate from finished missions swings from "?" to far too
short (it said 11 s with about 3 minutes to go). What one step of the batch costs is close to an overhead plus a
share per mission still flying, so the estimate here models the step's wall time as

    dt = a + b * running                          fitted by least squares on every step so far

and bounds what is left by every mission still flying lasting to the episode cap (running can only fall):

    time left <= (cap - steps so far) * (a + b * running)

Before any mission has ended, a and b cannot be told apart, and the mean step time stands in for a + b * running.
The bound is exact when the missions still flying run to the cap, and shrinks to 0 as the last one ends.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from typing import Any


@dataclass
class StepCostModel:
    """Least-squares fit of a batch step's wall time on the number of missions flying it."""

    n: int = 0
    sum_x: float = 0.0
    sum_y: float = 0.0
    sum_xx: float = 0.0
    sum_xy: float = 0.0

    def add(self, running: int, dt_s: float) -> None:
        self.n += 1
        self.sum_x += running
        self.sum_y += dt_s
        self.sum_xx += running * running
        self.sum_xy += running * dt_s

    def step_s(self, running: int) -> float:
        """The fitted wall time of one step with ``running`` missions flying (the mean step before the fit exists)."""
        if self.n == 0:
            return 0.0
        mean_x, mean_y = self.sum_x / self.n, self.sum_y / self.n
        var_x = self.sum_xx / self.n - mean_x * mean_x
        if var_x <= 1e-9 * max(1.0, mean_x * mean_x):
            return mean_y
        b = max(0.0, (self.sum_xy / self.n - mean_x * mean_y) / var_x)
        a = max(0.0, mean_y - b * mean_x)
        return a + b * running


@dataclass
class TimeLeft:
    """The time-left bound of the module docstring for ``missions`` missions of at most ``cap`` steps."""

    missions: int
    cap: int
    steps: int = 0
    running: int = -1
    model: StepCostModel | None = None

    def __post_init__(self) -> None:
        if self.running < 0:
            self.running = self.missions
        if self.model is None:
            self.model = StepCostModel()

    def step(self, flying: int, still_flying: int, dt_s: float) -> None:
        """One step of the batch took ``dt_s``: ``flying`` missions flew it, ``still_flying`` fly on."""
        assert self.model is not None
        self.model.add(flying, dt_s)
        self.steps += 1
        self.running = still_flying

    @property
    def seconds(self) -> float:
        assert self.model is not None
        if self.running == 0:
            return 0.0
        return max(0, self.cap - self.steps) * self.model.step_s(self.running)


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
        self.bar = self._stack.enter_context(
            progress_bar(
                total=missions,
                desc="missions",
                unit="mission",
                disable=disable,
                bar_format="{desc}: {n_fmt}/{total_fmt} |{bar}| [{elapsed}, {postfix}]",
            )
        )
        self.bar.set_postfix_str("time left ?", refresh=False)
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
            self.bar.set_postfix_str(f"at most {format_seconds(self.left.seconds)} left", refresh=False)
            self.bar.refresh()

    def __enter__(self) -> MissionBar:
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.close()


def format_seconds(seconds: float) -> str:
    """``12 s``, ``3:05`` or ``1:02:03``."""
    s = int(round(seconds))
    if s < 60:
        return f"{s} s"
    h, rest = divmod(s, 3600)
    m, sec = divmod(rest, 60)
    return f"{h}:{m:02d}:{sec:02d}" if h else f"{m}:{sec:02d}"
