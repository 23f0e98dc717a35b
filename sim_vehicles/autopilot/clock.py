"""The clocks a SITL world keeps and its vehicles read: simulated, link-model, wall and Unix time."""

from __future__ import annotations

from dataclasses import dataclass, field

from tssac_core.wire import units


@dataclass
class Clock:
    """Times the runner keeps and its vehicles read."""

    sim_s: float = 0.0
    """Simulated time (s since boot)."""
    link_s: float = 0.0
    """The link models' clock (see :mod:`sim_vehicles.link.link_model`)."""
    wall_s: float = 0.0
    """time.monotonic() of the current loop iteration."""
    unix_start_s: float = 0.0
    """Unix time of simulated time 0 (SYSTEM_TIME, tlog timestamps)."""
    lockstep: bool = False
    """The world runs in lockstep: every SYSTEM_TIME is a step tick, delayed by the link but never lost."""
    _boot_ms: tuple[float, int] = field(default=(0.0, 0), init=False, repr=False, compare=False)
    """(sim_s, time_boot_ms) of the last conversion: every frame of a step reads the same time."""

    @property
    def time_boot_ms(self) -> int:
        """Simulated time in whole milliseconds (``time_boot_ms``), converted once per value of :attr:`sim_s`."""
        sim_s, ms = self._boot_ms
        if sim_s != self.sim_s:
            ms = units.ms_from_s(self.sim_s)
            self._boot_ms = (self.sim_s, ms)
        return ms
