"""Sensor and datalink models read from a scenario's ``link:`` section (seeded, deterministic).

:class:`GpsReceiver` — what the position messages carry. Fixes fall due every 1 / ``gps_rate_hz``
simulated seconds and are taken at the first world step at or after that instant (so the effective
rate is at most 1 / dt). Each due fix is lost with probability ``gps_dropout_prob``; otherwise it is
the true position and velocity plus independent zero-mean Gaussian noise per horizontal axis,
sigma ``gps_position_sigma_m`` and ``gps_velocity_sigma_m_s`` (white: no correlation between fixes).

:class:`LinkChannel` — one direction of one vehicle's datalink, applied to whole UDP datagrams:

* loss: each datagram is dropped with probability ``packet_loss``;
* duplication: a delivered datagram is delivered twice with probability ``duplication``;
* latency: delivered ``latency_ms`` after it was sent;
* reordering: with probability ``reordering`` a datagram is held back until the next datagram of
  the channel has been delivered (at most :data:`REORDER_HOLD_MAX_S` past its due time).

Channel time is the caller's *link clock*: scaled wall time (simulated seconds while the simulation
keeps real time or a speed-up), simulated time while a lockstep world steps — see
:mod:`sim_vehicles.world_runner`.

Random draws: an item pushed with a ``key`` (an int naming it: message id, step, occurrence) gets its
loss, duplication and reordering draws from a hash of the channel's seed and that key, not from the
channel's sequence; items without a key draw from the sequence. So the fate of a step's telemetry or of
the setpoint that answers it does not depend on how many heartbeats, retries or wall-clock-timed frames
went through the channel before: a lockstep mission over a lossy link is repeatable. ``lossless`` items
(the lockstep tick) are only delayed.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections import deque
from dataclasses import dataclass, field
from typing import Generic, TypeVar

import numpy as np

from tssac_core.sim.scenario import LinkModel

REORDER_HOLD_MAX_S = 0.2
"""A held-back datagram is released at the latest this long after it was due, next datagram or not."""
_EPS_S = 1e-9

D = TypeVar("D")


@dataclass(frozen=True)
class GpsFix:
    """One GPS measurement, in the world's frame (east/north metres from the area's SW corner)."""

    time_s: float
    """Simulated time of the fix."""
    east_m: float
    north_m: float
    vel_east_m_s: float
    vel_north_m_s: float


class GpsReceiver:
    """Fix schedule, dropouts and noise of one vehicle's GPS (see the module docstring)."""

    def __init__(self, model: LinkModel, rng: np.random.Generator) -> None:
        self._period_s = 1.0 / model.gps_rate_hz
        self._dropout = model.gps_dropout_prob
        self._pos_sigma = model.gps_position_sigma_m
        self._vel_sigma = model.gps_velocity_sigma_m_s
        self._rng = rng
        self._next_index = 0
        self.last_fix: GpsFix | None = None
        self.fixes = 0
        self.dropouts = 0

    def sample(
        self, time_s: float, east_m: float, north_m: float, vel_east_m_s: float, vel_north_m_s: float
    ) -> GpsFix | None:
        """Called at every world step with the true state; returns a new fix if one fell due and survived."""
        if time_s + _EPS_S < self._next_index * self._period_s:
            return None
        # Fixes due since the last step collapse into one, taken now (the world has no state in between).
        self._next_index = int(math.floor(time_s / self._period_s + _EPS_S)) + 1
        u, n = self._rng.random(), self._rng.standard_normal(4).tolist()
        if u < self._dropout:
            self.dropouts += 1
            return None
        fix = GpsFix(
            time_s=time_s,
            east_m=east_m + self._pos_sigma * n[0],
            north_m=north_m + self._pos_sigma * n[1],
            vel_east_m_s=vel_east_m_s + self._vel_sigma * n[2],
            vel_north_m_s=vel_north_m_s + self._vel_sigma * n[3],
        )
        self.fixes += 1
        self.last_fix = fix
        return fix

    def has_fix(self, time_s: float) -> bool:
        """A 3D fix no older than 0.5 s or two fix periods, whichever is longer (the GPS health bit)."""
        if self.last_fix is None:
            return False
        return time_s - self.last_fix.time_s <= max(0.5, 2.0 * self._period_s) + _EPS_S


@dataclass
class LinkModelCounters:
    """What a channel did to the datagrams pushed into it."""

    pushed: int = 0
    lost: int = 0
    duplicated: int = 0
    reordered: int = 0
    delivered: int = 0


@dataclass(order=True)
class _Queued(Generic[D]):
    release_s: float
    seq: int
    item: D = field(compare=False)


class LinkChannel(Generic[D]):
    """One direction of a datalink (see the module docstring); items are opaque (datagram + address)."""

    def __init__(self, model: LinkModel, rng: np.random.Generator) -> None:
        self._loss = model.packet_loss
        self._dup = model.duplication
        self._reorder = model.reordering
        self._latency_s = model.latency_ms / 1000.0
        self._rng = rng
        self._key_seed = int(rng.integers(0, 2**63))
        self._ideal = self._loss == 0.0 and self._dup == 0.0 and self._reorder == 0.0 and self._latency_s == 0.0
        self._ready: deque[D] = deque()  # the ideal channel's fast path: delivered in order, at once
        self._heap: list[_Queued[D]] = []
        self._seq = itertools.count()
        self._held: tuple[_Queued[D], float] | None = None  # (datagram, hold deadline)
        self.counters = LinkModelCounters()

    @property
    def ideal(self) -> bool:
        return self._ideal

    def push(self, now_s: float, item: D, key: int | None = None, lossless: bool = False) -> None:
        """Send ``item`` into the channel at link time ``now_s`` (``key``, ``lossless``: see the module docstring)."""
        self.counters.pushed += 1
        if self._ideal:
            self._ready.append(item)
            return
        if lossless:
            heapq.heappush(self._heap, _Queued(now_s + self._latency_s, next(self._seq), item))
            return
        u_loss, u_dup, u_reorder = self._rng.random(3) if key is None else keyed_uniforms(self._key_seed, key)
        if u_loss < self._loss:
            self.counters.lost += 1
            return
        release = now_s + self._latency_s
        entry = _Queued(release, next(self._seq), item)
        if self._held is not None:
            # The held datagram goes out right behind this one.
            held, _deadline = self._held
            self._held = None
            heapq.heappush(self._heap, entry)
            heapq.heappush(self._heap, _Queued(max(held.release_s, release), next(self._seq), held.item))
        elif u_reorder < self._reorder:
            self.counters.reordered += 1
            self._held = (entry, release + REORDER_HOLD_MAX_S)
        else:
            heapq.heappush(self._heap, entry)
        if u_dup < self._dup:
            self.counters.duplicated += 1
            heapq.heappush(self._heap, _Queued(release, next(self._seq), item))

    def pop_due(self, now_s: float) -> list[D]:
        """Items whose delivery time has come, in delivery order."""
        if self._ideal:
            ready = list(self._ready)
            self._ready.clear()
            self.counters.delivered += len(ready)
            return ready
        out: list[D] = []
        if self._held is not None and now_s + _EPS_S >= self._held[1]:
            heapq.heappush(self._heap, self._held[0])
            self._held = None
        while self._heap and self._heap[0].release_s <= now_s + _EPS_S:
            out.append(heapq.heappop(self._heap).item)
        self.counters.delivered += len(out)
        return out

    def next_due_s(self) -> float | None:
        """Link time of the next delivery (or hold deadline), None if nothing is queued."""
        times = []
        if self._ready:
            return -math.inf
        if self._heap:
            times.append(self._heap[0].release_s)
        if self._held is not None:
            times.append(self._held[1])
        return min(times) if times else None


_MASK64 = (1 << 64) - 1


def _mix64(x: int) -> int:
    """SplitMix64's finaliser: a bijective scramble of 64 bits."""
    x = (x + 0x9E3779B97F4A7C15) & _MASK64
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & _MASK64
    return x ^ (x >> 31)


def keyed_uniforms(seed: int, key: int) -> tuple[float, float, float]:
    """Three uniforms in [0, 1) determined by (seed, key) alone."""
    h = _mix64(seed ^ _mix64(key & _MASK64))
    out = []
    for _ in range(3):
        h = _mix64(h)
        out.append((h >> 11) * (1.0 / (1 << 53)))
    return out[0], out[1], out[2]
