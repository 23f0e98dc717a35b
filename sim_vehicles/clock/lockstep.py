"""Lockstep (``--lockstep``): the world holds at step 0 until every vehicle (``LockstepStart.ALL``) or any (``ANY``)
holds the world, that is, is armed in GUIDED and its client has answered a tick. From then on it takes a step as soon
as every vehicle in the loop (:attr:`~sim_vehicles.clock.policy.ClockLink.holds_world`) has answered the newest tick
its datalink delivered, itself or by a grant (:mod:`tssac_core.wire.lockstep`), and steps on while the answers that
arrive at the new step already answer it. A vehicle in the loop that sends nothing for its setpoint timeout of *wall*
time fails safe and stops holding the world. While nobody is in the loop the world runs on the real-time schedule
(times ``speedup``).

The link clock: while the world holds at the start no simulated time passes and what the links carry crosses at once
(in order, each frame still lost as the link model draws it), so the clients' handshake costs no wall time and reaches
them the same way in every run; while the world steps in lockstep, and while it lingers, the link runs on simulated
time (it stands still at the barrier); while it runs paced, on wall time times ``speedup``. After the mission's end
the linger's simulated seconds are served at once, each with its tick."""

from __future__ import annotations

import logging
from collections.abc import Sequence

from sim_vehicles.autopilot.clock import Clock
from sim_vehicles.clock.policy import MAX_CATCHUP_STEPS, ClockLink, Phase, Stepper, TakeStep, gate_open
from tssac_core.sim.sitl_config import LockstepStart

_log = logging.getLogger(__name__)


class LockstepClock:
    """The lockstep clock policy (:class:`~sim_vehicles.clock.policy.ClockPolicy`; see the module docstring)."""

    ticks = True
    """After every step each vehicle sends SYSTEM_TIME, the step's tick, so a client sees every step even when its
    other streams are slower than the step rate."""

    def __init__(
        self,
        clock: Clock,
        links: Sequence[ClockLink],
        take_step: TakeStep,
        dt_s: float,
        speedup: float,
        start: LockstepStart,
        linger_s: float,
    ) -> None:
        self._steps = Stepper(clock, links, take_step, dt_s, speedup, linger_s, ticks=True)
        self._steps.phase = Phase.HOLD
        self._start = start
        self._paced = False
        """Nobody in the loop: the world runs at real time x speedup."""
        self._barrier_wall_s = 0.0
        """Wall time the world last stepped, or began to wait for its vehicles."""

    @property
    def phase(self) -> Phase:
        return self._steps.phase

    def start(self, now_wall: float) -> None:
        self._steps.start(now_wall)
        self._paced = False
        self._barrier_wall_s = now_wall

    @property
    def _link_on_sim_time(self) -> bool:
        """Lockstep steps drive the link clock (it stands still while the world waits at the barrier), and so do the
        linger's steps."""
        phase = self._steps.phase
        return phase is Phase.LINGER or (phase is Phase.RUN and not self._paced)

    def tick(self, now_wall: float) -> None:
        s = self._steps
        if s.phase is Phase.HOLD:
            s.fast_forward_link()
        elif not self._link_on_sim_time:
            s.link_by_wall(now_wall)
        s.clock.wall_s = now_wall

    def at_sim_time(self, sim_s: float) -> None:
        self._steps.set_sim_time(sim_s, self._link_on_sim_time)

    def link_wait_s(self) -> float | None:
        """Held at the start: none if the links carry something (the next iteration delivers it). On simulated time
        only steps bring the links' deliveries closer; paced, wall time does."""
        s = self._steps
        if s.phase is Phase.HOLD:
            return 0.0 if any(link.next_link_due_s() is not None for link in s.links) else None
        if self._link_on_sim_time:
            return None
        return s.link_wait_by_wall_s()

    def advance(self, now_wall: float) -> float | None:
        s = self._steps
        if s.phase is Phase.HOLD:
            if not gate_open([link.holds_world for link in s.links], self._start):
                return s.keepalive(now_wall)
            _log.info("start gate open, the world starts")
            # The last client's answer reached the socket only now: it crosses the link before the first step, as the
            # others' did (which answer comes last is the wall clock's choice; the mission must not be).
            s.fast_forward_link()
            for link in s.links:
                link.process_incoming()
                link.flush()
            s.phase = Phase.RUN
            self._barrier_wall_s = now_wall
            s.schedule.anchor(now_wall, s.clock.sim_s)
        if s.phase is Phase.RUN:
            return self._run(now_wall)
        if s.phase is Phase.LINGER:
            return s.linger(now_wall, at_once=True)
        return None

    def _run(self, now_wall: float) -> float:
        """Paced while nobody is in the loop; else the barrier: fail safe who stayed silent too long, wait for who has
        not answered, step when everyone has."""
        s = self._steps
        if not any(link.holds_world for link in s.links):
            if not self._paced:
                _log.info("lockstep: no vehicle in the loop; running at %g x real time", s.speedup)
                self._paced = True
                s.schedule.anchor(now_wall, s.clock.sim_s)
            return s.paced(now_wall)
        if self._paced:
            self._paced = False
            self._barrier_wall_s = now_wall
        waiting = self._waiting(now_wall)
        if waiting:
            return min([s.keepalive(now_wall)] + [self._silence_deadline(link) for link in waiting])
        if not any(link.holds_world for link in s.links):
            return now_wall  # every waiting vehicle just failed safe: run paced from the next iteration
        return self._step_round(now_wall)

    def _silence_deadline(self, link: ClockLink) -> float:
        """The wall time at which a vehicle that has not answered fails safe."""
        return max(self._barrier_wall_s, link.vehicle.loop_since_wall_s) + link.vehicle.setpoint_timeout_s

    def _waiting(self, now_wall: float) -> list[ClockLink]:
        """The vehicles in the loop that have not answered, once those silent for longer than their setpoint timeout
        (wall time: simulated time stands still while the world waits) have failed safe."""
        waiting = [link for link in self._steps.links if link.holds_world and not link.answered()]
        for link in waiting:
            v = link.vehicle
            since = max(self._barrier_wall_s, v.loop_since_wall_s)
            if now_wall - since > v.setpoint_timeout_s:
                v.enter_failsafe(f"no setpoint for {v.setpoint_timeout_s:g} s wall")
        return [link for link in waiting if link.holds_world]

    def _step_round(self, now_wall: float) -> float:
        """Everyone in the loop has answered: step, and step on while the answers the links deliver at the new step
        answer it too (:data:`MAX_CATCHUP_STEPS` at most). The wall time to look again: now if more steps are due or
        the mission ended (its linger runs at once), else when the first vehicle's silence would fail it safe."""
        s = self._steps
        n = 0
        while True:
            s.step()
            self._barrier_wall_s = now_wall
            n += 1
            if s.phase is not Phase.RUN or n == MAX_CATCHUP_STEPS:
                break
            # Setpoints the link delivers at the new step time are flown from it on.
            for link in s.links:
                link.process_incoming()
            # With link latency the newest tick the clients have seen may already be answered: step on.
            if not all(link.answered() for link in s.links if link.holds_world) or not any(
                link.holds_world for link in s.links
            ):
                break
        if n == MAX_CATCHUP_STEPS or s.phase is not Phase.RUN:
            return now_wall
        return now_wall + min(link.vehicle.setpoint_timeout_s for link in s.links)
