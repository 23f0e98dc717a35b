"""The companion's estimate of the vehicle clock's rate (mavlink_bridge.companion.clock_rate)."""

from __future__ import annotations

import pytest

from mavlink_bridge.companion.clock_rate import WINDOW_S, ClockRate


def test_a_rate_comes_after_a_whole_window_and_averages_the_windows():
    clock = ClockRate()
    clock.seen(10.0, 0)
    clock.seen(10.0 + WINDOW_S - 0.01, 4900)  # within the first window: not yet
    assert clock.rate is None
    clock.seen(10.5, 5000)  # 5 vehicle seconds in half a wall second
    assert clock.rate == pytest.approx(10.0)
    clock.seen(11.0, 6000)  # the next window runs at 2x: averaged with the estimate so far
    assert clock.rate == pytest.approx(6.0)


def test_a_stalled_vehicle_clock_drives_the_rate_towards_zero():
    clock = ClockRate()
    for k in range(6):
        clock.seen(float(k), 1000 if k else 0)  # one vehicle second, then the vehicle's clock stands still
    assert clock.rate is not None and clock.rate < 0.1
