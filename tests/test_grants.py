"""A companion's lockstep grants (mavlink_bridge.companion.grants): one answer stands for the ticks up to the next
decision, within the longest grant, and never through a tick at which the gap hold could fire or the flight ends."""

from __future__ import annotations

from mavlink_bridge.companion.grants import GrantRule

DT = 100


def rule(enabled: bool = True, fixes_every_tick: bool = True, max_grant_ms: int = 1000) -> GrantRule:
    return GrantRule(enabled=enabled, dt_ms=DT, max_grant_ms=max_grant_ms, fixes_every_tick=fixes_every_tick)


def never(_tick_ms: int) -> bool:
    return False


def test_a_grant_reaches_the_tick_before_the_next_decision_within_the_longest_grant():
    assert rule().through_ms(5000, next_decision_step=60, gap_may_hold=never, duration_over=None) == 5900
    assert rule(max_grant_ms=300).through_ms(5000, 60, never, None) == 5300
    assert rule().through_ms(5000, 51, never, None) is None  # the next tick decides: no grant
    assert rule(enabled=False).through_ms(5000, 60, never, None) is None


def test_a_grant_stops_before_a_tick_at_which_the_gap_hold_could_fire():
    gap_from_5400 = rule(fixes_every_tick=False)
    assert gap_from_5400.through_ms(5000, 60, lambda t: t >= 5400, None) == 5300
    assert gap_from_5400.through_ms(5000, 60, lambda t: t >= 5100, None) is None
    assert rule(fixes_every_tick=True).through_ms(5000, 60, lambda t: t >= 5100, None) == 5900  # a fix every tick


def test_a_grant_ends_with_the_flights_last_tick():
    def over_at_5600(t: int) -> bool:
        return t >= 5600

    assert rule().through_ms(5000, 60, never, over_at_5600) == 5600
    assert rule().through_ms(5600, 70, never, over_at_5600) is None  # this tick's answer is the flight's last
