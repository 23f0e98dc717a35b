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
estimate; the shards fly at once, so what is left is the largest of them (``evaluate``'s bar).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

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
    clock_s: float = field(default_factory=time.perf_counter)
    """When the last step ended (or the estimate was made): :meth:`tick` times a step from it."""

    def __post_init__(self) -> None:
        if self.running < 0:
            self.running = self.missions

    def step(self, flying: int, still_flying: int, dt_s: float) -> None:
        """One step of the batch took ``dt_s``: ``flying`` missions flew it, ``still_flying`` fly on."""
        if self.steps > 0:
            self.timed_s += dt_s
        self.steps += 1
        self.running = still_flying

    def tick(self, flying: int, still_flying: int) -> None:
        """:meth:`step` timed on the wall clock since the last tick (``fly_missions``' ``on_step``)."""
        now = time.perf_counter()
        self.step(flying, still_flying, now - self.clock_s)
        self.clock_s = now

    @property
    def seconds(self) -> float | None:
        """The estimate; None before :data:`MIN_TIMED_STEPS` steps after the first have been timed."""
        if self.running == 0:
            return 0.0
        if self.steps <= MIN_TIMED_STEPS:
            return None
        return max(0, self.cap - self.steps) * self.timed_s / (self.steps - 1)


@dataclass(frozen=True)
class ShardProgress:
    """What a shard of missions flown on a worker reports: the missions it finished since its last report, and its
    own time left then (None: not known yet)."""

    shard: int
    finished: int
    seconds_left: float | None
