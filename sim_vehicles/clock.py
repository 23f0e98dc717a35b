"""The clocks a SITL world keeps and its vehicles read: simulated, link-model, wall and Unix time."""

from __future__ import annotations

from dataclasses import dataclass

from tssac_core.wire import units


@dataclass
class Clock:
    """Times the runner keeps and its vehicles read."""

    sim_s: float = 0.0
    """Simulated time (s since boot)."""
    link_s: float = 0.0
    """The link models' clock (see :mod:`sim_vehicles.link_model`)."""
    wall_s: float = 0.0
    """time.monotonic() of the current loop iteration."""
    unix_start_s: float = 0.0
    """Unix time of simulated time 0 (SYSTEM_TIME, tlog timestamps)."""
    lockstep: bool = False
    """The world runs in lockstep: every SYSTEM_TIME is a step tick, delayed by the link but never lost."""

    @property
    def time_boot_ms(self) -> int:
        return units.ms_from_s(self.sim_s)
