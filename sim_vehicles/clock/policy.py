"""What a clock policy is (:class:`ClockPolicy`), what it reads of the vehicles and their links (:class:`ClockLink`),
and what both policies do alike (:class:`Stepper`: the phase, taking a step, the real-time schedule, the snapshots
while the world holds still, the linger after the mission's end).

A mission's world goes through the phases of :class:`Phase`: it may hold at step 0 until the start gate opens (its
vehicles armed in GUIDED), then runs, then lingers ``linger_s`` simulated seconds with the world frozen, then is done.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Sequence
from typing import Protocol

from sim_vehicles.autopilot.clock import Clock
from sim_vehicles.autopilot.modes import FlightMode
from sim_vehicles.clock.pacing import EPS, PacedSchedule
from tssac_core.sim.sitl_config import LockstepStart

MAX_CATCHUP_STEPS = 20
"""Steps taken per loop iteration at most, so that I/O is never starved."""
KEEPALIVE_S = 1.0
"""Wall seconds between snapshots while a world holds still."""


class Phase(enum.Enum):
    """Where a mission's world is in its run."""

    HOLD = "hold"
    """At step 0 until the start gate opens (lockstep, or real time with ``hold_start``)."""
    RUN = "run"
    """Stepping."""
    LINGER = "linger"
    """The mission has ended; the vehicles serve ``linger_s`` more simulated seconds, the world frozen."""
    DONE = "done"
    """The run is over."""


TakeStep = Callable[[], int | None]
"""One world step, its telemetry sent: the step the mission ended at, or None while it goes on."""


class ClockVehicle(Protocol):
    """What a clock policy reads of a vehicle (:class:`sim_vehicles.autopilot.vehicle.Vehicle`)."""

    @property
    def armed(self) -> bool: ...
    @property
    def mode(self) -> FlightMode: ...
    @property
    def setpoint_timeout_s(self) -> float: ...
    @property
    def loop_since_wall_s(self) -> float:
        """Wall time the vehicle last came into the lockstep loop."""
        ...

    def enter_failsafe(self, reason: str) -> None: ...


class ClockLink(Protocol):
    """What a clock policy reads of, and does with, a vehicle's link
    (:class:`sim_vehicles.protocol.vehicle_link.VehicleLink`)."""

    @property
    def vehicle(self) -> ClockVehicle: ...
    @property
    def holds_world(self) -> bool:
        """A member of the lockstep barrier: in the loop, and its client has answered a tick since."""
        ...

    def answered(self) -> bool:
        """The client has answered the newest step tick its datalink delivered."""
        ...

    def next_link_due_s(self) -> float | None:
        """Link time at which the link next has something to deliver."""
        ...

    def process_incoming(self) -> None: ...
    def flush(self) -> None: ...
    def publish(self, tick: bool = False) -> None: ...
    def send_snapshot(self) -> None: ...


class ClockPolicy(Protocol):
    """How one clock mode advances a world: the world runner's loop calls :meth:`tick` at each iteration,
    :meth:`advance` to take the steps that are due, and waits on its sockets no longer than :meth:`link_wait_s` says."""

    @property
    def phase(self) -> Phase: ...
    @property
    def ticks(self) -> bool:
        """Every step (and linger step) sends SYSTEM_TIME, the step's tick (lockstep)."""
        ...

    def start(self, now_wall: float) -> None:
        """The loop starts at wall time ``now_wall``."""
        ...

    def tick(self, now_wall: float) -> None:
        """A loop iteration at ``now_wall``: the link clock moves on as the mode says, the wall clock to now."""
        ...

    def advance(self, now_wall: float) -> float | None:
        """Take the steps that are due; the wall time of the next planned action (None: the run is done)."""
        ...

    def at_sim_time(self, sim_s: float) -> None:
        """A world step has reached simulated time ``sim_s``: the clock is set to it (and the link clock follows it
        where the mode runs the link on simulated time)."""
        ...

    def link_wait_s(self) -> float | None:
        """Wall seconds until the links next deliver something, where waiting brings it closer (None: it does not)."""
        ...


def gate_open(ready: Sequence[bool], start: LockstepStart) -> bool:
    """The start gate: every vehicle ready (``ALL``) or any (``ANY``)."""
    return all(ready) if start is LockstepStart.ALL else any(ready)


class Stepper:
    """What both clock policies do alike on one mission's ``clock``: the phase, each step taken (with the bookkeeping
    of the mission's end), the real-time schedule and its steps, the snapshots while the world holds still, and the
    linger after the end."""

    def __init__(
        self,
        clock: Clock,
        links: Sequence[ClockLink],
        take_step: TakeStep,
        dt_s: float,
        speedup: float,
        linger_s: float,
        ticks: bool,
    ) -> None:
        self.clock = clock
        self.links = links
        self.take_step = take_step
        self.dt_s = dt_s
        self.speedup = speedup
        self.linger_s = linger_s
        self.ticks = ticks
        """Every step and linger step sends its tick (lockstep)."""
        self.schedule = PacedSchedule(dt_s, speedup)
        self.phase = Phase.RUN
        self.last_output_wall_s = 0.0
        """Wall time of the last step or snapshot (the next snapshot is due :data:`KEEPALIVE_S` after it)."""
        self._end_step = 0
        """The step the mission ended at."""
        self._end_sim_s = 0.0
        self._linger_steps = 0

    def start(self, now_wall: float) -> None:
        """The loop starts: the schedule counts from now, and so does the keepalive."""
        self.schedule.anchor(now_wall, self.clock.sim_s)
        self.last_output_wall_s = now_wall

    def step(self) -> None:
        """One world step; at the mission's end the linger begins, its schedule counting from now."""
        ended_at = self.take_step()
        self.last_output_wall_s = self.clock.wall_s
        if ended_at is not None:
            self.phase = Phase.LINGER
            self._end_step = ended_at
            self._end_sim_s = self.clock.sim_s
            self.schedule.anchor(self.clock.wall_s, self.clock.sim_s)

    def set_sim_time(self, sim_s: float, link_on_sim_time: bool) -> None:
        """The clock at simulated time ``sim_s``; the link clock moves with it if ``link_on_sim_time``."""
        if link_on_sim_time:
            self.clock.link_s += sim_s - self.clock.sim_s
        self.clock.sim_s = sim_s

    def link_by_wall(self, now_wall: float) -> None:
        """The link clock moves with wall time times ``speedup``."""
        self.clock.link_s += (now_wall - self.clock.wall_s) * self.speedup

    def link_wait_by_wall_s(self) -> float | None:
        """With the link clock on wall time: wall seconds until the links' next delivery (None: nothing in flight)."""
        waits = []
        for link in self.links:
            due = link.next_link_due_s()
            if due is not None:
                waits.append((due - self.clock.link_s) / self.speedup)
        return min(waits) if waits else None

    def fast_forward_link(self) -> None:
        """The link clock to the last delivery the links hold: everything in flight arrives now."""
        due = [d for d in (link.next_link_due_s() for link in self.links) if d is not None]
        self.clock.link_s = max([self.clock.link_s, *due])

    def paced(self, now_wall: float) -> float:
        """The steps the real-time schedule says are due (:data:`MAX_CATCHUP_STEPS` at most); the wall time of the
        next one (now if more are due)."""
        n = 0
        while self.phase is Phase.RUN and n < MAX_CATCHUP_STEPS and self.schedule.step_due(now_wall, self.clock.sim_s):
            self.step()
            n += 1
        return now_wall if n == MAX_CATCHUP_STEPS else self.schedule.next_step_wall(self.clock.sim_s)

    def keepalive(self, now_wall: float) -> float:
        """While the world holds still: each vehicle's snapshot once per :data:`KEEPALIVE_S` wall seconds; the wall
        time of the next one."""
        if now_wall - self.last_output_wall_s >= KEEPALIVE_S:
            self.last_output_wall_s = now_wall
            for link in self.links:
                link.send_snapshot()
        return self.last_output_wall_s + KEEPALIVE_S

    def linger(self, now_wall: float, at_once: bool) -> float | None:
        """Serve ``linger_s`` more simulated seconds, the world frozen: on the real-time schedule, or ``at_once``
        (lockstep: the link on simulated time, so what was sent with less latency than the linger is delivered, as at
        real time, and no wall time is spent waiting for nothing). The wall time of the next linger step; None once
        the linger is over (the run is done)."""
        end_s = self._end_sim_s + self.linger_s
        n = 0
        while (
            self.clock.sim_s + EPS < end_s
            and n < MAX_CATCHUP_STEPS
            and (at_once or self.schedule.step_due(now_wall, self.clock.sim_s))
        ):
            self._linger_steps += 1
            self.set_sim_time((self._end_step + self._linger_steps) * self.dt_s, link_on_sim_time=at_once)
            for link in self.links:
                link.publish(tick=self.ticks)
            n += 1
        if self.clock.sim_s + EPS >= end_s:
            self.phase = Phase.DONE
            return None
        return now_wall if at_once else self.schedule.next_step_wall(self.clock.sim_s)
