"""The vehicle's clock as a companion follows it (mavlink_bridge.companion.tick_clock): when a control step is due, how
long a receive may wait, the extrapolated ticks off lockstep, and what tells the time under lockstep."""

from __future__ import annotations

import pytest

from mavlink_bridge.companion.tick_clock import WAIT_S, TickClock

DT_MS = 100
SETTLE_S = 0.005


def test_a_new_tick_is_due_once_its_fix_is_there_or_its_settling_time_is_over():
    ticks = TickClock(DT_MS, lockstep=False, settle_s=SETTLE_S)
    assert ticks.due(10.0, 10.0) is None and ticks.wait_s(True, 10.0) == WAIT_S  # no vehicle time yet
    ticks.seen(1000, 10.0)
    assert ticks.tick_due()
    assert ticks.due(10.001, 10.0) is None  # its fix is probably on its way
    assert ticks.wait_s(True, 10.001) == pytest.approx(SETTLE_S - 0.001)
    assert ticks.wait_s(False, 10.001) == WAIT_S  # not flying: nothing to control
    due = ticks.due(10.006, 10.0)
    assert due is not None and (due.t_ms, due.trigger_rx_s, due.extrapolated) == (1000, 10.0, False)
    ticks.fix(1000, 10.002)
    due = ticks.due(10.003, 10.0)
    assert due is not None and due.trigger_rx_s == 10.002  # the latency counts from the fix
    assert ticks.wait_s(True, 10.003) == 0.0
    assert ticks.controlled(1000) == 0
    assert not ticks.tick_due() and ticks.due(10.004, 10.0) is None


def test_under_lockstep_a_tick_waits_for_nothing_and_only_the_steps_tick_tells_the_time():
    ticks = TickClock(DT_MS, lockstep=True, settle_s=SETTLE_S)
    assert ticks.settle_s == 0.0
    assert ticks.stamps_time("SYSTEM_TIME") and not ticks.stamps_time("LOCAL_POSITION_NED")
    assert TickClock(DT_MS, lockstep=False, settle_s=SETTLE_S).stamps_time("LOCAL_POSITION_NED")
    assert not ticks.stamps_time("HEARTBEAT")
    ticks.seen(500, 1.0)
    due = ticks.due(1.0, 1.0)
    assert due is not None and due.t_ms == 500  # no fix: the link lost it, the tick is flown without
    assert ticks.later_tick_read(600) and not ticks.later_tick_read(500)
    ticks.controlled(500)
    assert not ticks.later_tick_read(600)  # nothing due: the frame is read as it comes


def test_skipped_ticks_are_counted_and_a_restart_is_a_clock_gone_back():
    ticks = TickClock(DT_MS, lockstep=False, settle_s=SETTLE_S)
    ticks.seen(3000, 0.0)
    ticks.controlled(3000)
    assert ticks.controlled(3400) == 3
    assert not ticks.went_back(2000, restart_jump_s=1.0)  # late, not a restart
    assert ticks.went_back(1999, restart_jump_s=1.0)
    ticks.seen(2900, 0.1)  # older than the newest: kept as it was
    assert ticks.vt_ms == 3000


def test_off_lockstep_the_clock_is_extrapolated_at_its_rate_while_the_vehicle_is_silent():
    ticks = TickClock(DT_MS, lockstep=False, settle_s=SETTLE_S)
    ticks.seen(0, 0.0)
    ticks.seen(5000, 0.5)  # 10 vehicle seconds per wall second
    assert ticks.rate == pytest.approx(10.0) and ticks.extrapolating()
    ticks.controlled(5000)
    assert ticks.wait_s(True, 0.5) == pytest.approx(0.5 * 0.1 / 10.0)
    assert ticks.due(0.51, last_rx_s=0.5) is None  # silent for less than 1.5 ticks
    due = ticks.due(0.53, last_rx_s=0.5)
    assert due is not None and (due.t_ms, due.trigger_rx_s, due.extrapolated) == (5300, None, True)
    assert not TickClock(DT_MS, lockstep=True, settle_s=SETTLE_S).extrapolating()
