"""How a SITL world's time advances, one policy per clock mode: when its next step is due, how long its loop may wait,
what a lockstep answer lets it do, and how it lingers after the mission's end. ``policy`` (what a policy is, what it
reads of the vehicles and their links, and what both policies do alike) · ``pacing`` (the real-time schedule) ·
``paced`` (real time x speedup, optionally held at the start) · ``lockstep`` (a step per round of setpoints).
:func:`clock_policy` picks the mode's policy; the world runner (:mod:`sim_vehicles.world_runner`) asks it and takes the
steps. The clocks the vehicles read are :class:`sim_vehicles.autopilot.clock.Clock`. Above the autopilot."""

from __future__ import annotations

from collections.abc import Sequence

from sim_vehicles.autopilot.clock import Clock
from sim_vehicles.clock.lockstep import LockstepClock
from sim_vehicles.clock.paced import PacedClock
from sim_vehicles.clock.policy import ClockLink, ClockPolicy, Phase, TakeStep
from tssac_core.sim.sitl_config import ClockMode, SitlConfig

__all__ = ["ClockPolicy", "LockstepClock", "PacedClock", "Phase", "clock_policy"]


def clock_policy(config: SitlConfig, clock: Clock, links: Sequence[ClockLink], take_step: TakeStep) -> ClockPolicy:
    """The policy of ``config``'s clock mode for one mission: its world's ``clock``, its vehicles' ``links``, and
    ``take_step``, which takes one world step."""
    dt_s = config.scenario.dt_s
    if config.clock is ClockMode.LOCKSTEP:
        return LockstepClock(clock, links, take_step, dt_s, config.speedup, config.lockstep_start, config.linger_s)
    return PacedClock(
        clock, links, take_step, dt_s, config.speedup, config.lockstep_start, config.linger_s, config.hold_start
    )
