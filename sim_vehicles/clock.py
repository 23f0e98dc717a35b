"""The clocks a SITL world keeps and its vehicles read: simulated, link-model, wall and Unix time."""

from __future__ import annotations

from tssac_core.wire import units


class Clock:
    """Times the runner keeps and its vehicles read."""

    def __init__(
        self,
        sim_s: float = 0.0,
        link_s: float = 0.0,
        wall_s: float = 0.0,
        unix_start_s: float = 0.0,
        lockstep: bool = False,
    ) -> None:
        self.sim_s = sim_s
        self.link_s = link_s
        """The link models' clock (see :mod:`sim_vehicles.link_model`)."""
        self.wall_s = wall_s
        """time.monotonic() of the current loop iteration."""
        self.unix_start_s = unix_start_s
        """Unix time of simulated time 0 (SYSTEM_TIME, tlog timestamps)."""
        self.lockstep = lockstep
        """The world runs in lockstep: every SYSTEM_TIME is a step tick, delayed by the link but never lost."""

    @property
    def sim_s(self) -> float:
        """Simulated time (s since boot)."""
        return self._sim_s

    @sim_s.setter
    def sim_s(self, value: float) -> None:
        self._sim_s = value
        self._time_boot_ms = units.ms_from_s(value)

    @property
    def time_boot_ms(self) -> int:
        """Simulated time in whole milliseconds (``time_boot_ms``), converted once per change of :attr:`sim_s`."""
        return self._time_boot_ms

    def __repr__(self) -> str:
        return (
            f"Clock(sim_s={self.sim_s!r}, link_s={self.link_s!r}, wall_s={self.wall_s!r}, "
            f"unix_start_s={self.unix_start_s!r}, lockstep={self.lockstep!r})"
        )
