"""How fast the vehicle's clock runs against the companion's: vehicle seconds per wall second.

Off lockstep a SITL world may run at any speed-up, and a loaded machine slows it; the companion extrapolates the
vehicle's time between telemetry frames with this rate (its control ticks, and how long it may wait for the next
frame). The rate is measured over windows of at least half a wall second, each window's rate averaged with the
estimate so far.
"""

from __future__ import annotations

WINDOW_S = 0.5
"""The shortest wall-clock window a rate is measured over."""


class ClockRate:
    """The vehicle clock's rate, from the vehicle times seen and the wall times they were read at."""

    def __init__(self) -> None:
        self._start: tuple[float, int] | None = None
        """(wall seconds, vehicle ms) at the start of the current window."""
        self.rate: float | None = None
        """Vehicle seconds per wall second (None until one window has passed)."""

    def seen(self, wall_s: float, vehicle_ms: int) -> None:
        """A newer vehicle time ``vehicle_ms``, read at ``wall_s``."""
        if self._start is None:
            self._start = (wall_s, vehicle_ms)
            return
        w0, t0 = self._start
        if wall_s - w0 >= WINDOW_S:
            rate = (vehicle_ms - t0) / 1000.0 / (wall_s - w0)
            self.rate = rate if self.rate is None else 0.5 * (self.rate + rate)
            self._start = (wall_s, vehicle_ms)
