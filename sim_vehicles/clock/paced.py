"""Real time (``--speedup X``): step k of simulated time is due ``k * dt / X`` wall seconds after the start
(:class:`~sim_vehicles.clock.pacing.PacedSchedule`, re-anchored when the machine falls behind), and the link models run
on wall time times X. With ``hold_start`` the world first holds at step 0, as a lockstep world does, until the
``lockstep_start`` vehicles are armed in GUIDED. After the mission's end the linger runs on the same schedule."""

from __future__ import annotations

import logging
from collections.abc import Sequence

from sim_vehicles.autopilot.clock import Clock
from sim_vehicles.autopilot.modes import FlightMode
from sim_vehicles.clock.policy import ClockLink, Phase, Stepper, TakeStep, gate_open
from tssac_core.sim.sitl_config import LockstepStart

_log = logging.getLogger(__name__)


class PacedClock:
    """The real-time clock policy (:class:`~sim_vehicles.clock.policy.ClockPolicy`; see the module docstring)."""

    ticks = False
    """Off lockstep a step sends no tick of its own: SYSTEM_TIME keeps its stream's rate."""

    def __init__(
        self,
        clock: Clock,
        links: Sequence[ClockLink],
        take_step: TakeStep,
        dt_s: float,
        speedup: float,
        start: LockstepStart,
        linger_s: float,
        hold_start: bool,
    ) -> None:
        self._steps = Stepper(clock, links, take_step, dt_s, speedup, linger_s, ticks=False)
        self._start = start
        if hold_start:
            self._steps.phase = Phase.HOLD

    @property
    def phase(self) -> Phase:
        return self._steps.phase

    def start(self, now_wall: float) -> None:
        self._steps.start(now_wall)

    def tick(self, now_wall: float) -> None:
        """The link clock runs on wall time times ``speedup``, whatever the phase."""
        self._steps.link_by_wall(now_wall)
        self._steps.clock.wall_s = now_wall

    def at_sim_time(self, sim_s: float) -> None:
        self._steps.set_sim_time(sim_s, link_on_sim_time=False)

    def link_wait_s(self) -> float | None:
        return self._steps.link_wait_by_wall_s()

    def advance(self, now_wall: float) -> float | None:
        """Held: snapshots until the gate opens, then the schedule starts now (not when the world was created).
        Running and lingering: the steps the schedule says are due."""
        s = self._steps
        if s.phase is Phase.HOLD:
            armed_in_guided = [link.vehicle.armed and link.vehicle.mode is FlightMode.GUIDED for link in s.links]
            if not gate_open(armed_in_guided, self._start):
                return s.keepalive(now_wall)
            _log.info("start gate open, the world starts")
            s.phase = Phase.RUN
            s.schedule.anchor(now_wall, s.clock.sim_s)
        if s.phase is Phase.RUN:
            return s.paced(now_wall)
        if s.phase is Phase.LINGER:
            return s.linger(now_wall, at_once=False)
        return None
