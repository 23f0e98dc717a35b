"""How far a companion's lockstep answer may reach (:mod:`tssac_core.wire.lockstep`): the ticks after its own that one
setpoint answers for, so that the world need not wait for an answer at every tick that would repeat the one before.

A grant runs only in lockstep over a link that loses and reorders nothing. It never reaches a tick at which the
companion could decide otherwise: its pilot's or monitor's next decision, the end of ``--duration-s``, or a tick at
which the telemetry-gap hold could fire if no position fix came (where every tick brings a fix, that cannot happen).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from mavlink_bridge.companion.config import CompanionConfig
from tssac_core.wire.lockstep import granted_through_ms


@dataclass(frozen=True)
class GrantRule:
    """A companion's grants: whether it gives them, the tick, the longest, and whether a fix comes with every tick."""

    enabled: bool
    dt_ms: int
    max_grant_ms: int
    fixes_every_tick: bool
    """No GPS dropout and a fix per step: the telemetry-gap hold cannot fire while a grant runs."""

    @classmethod
    def of(cls, config: CompanionConfig) -> GrantRule:
        s, link = config.scenario, config.scenario.link
        lossless = link.packet_loss == 0 and link.reordering == 0
        return cls(
            enabled=config.lockstep and config.lockstep_grant_s > 0 and lossless,
            dt_ms=int(round(s.dt_s * 1000.0)),
            max_grant_ms=int(config.lockstep_grant_s * 1000.0),
            fixes_every_tick=link.gps_dropout_prob == 0 and link.gps_rate_hz * s.dt_s >= 1.0 - 1e-9,
        )

    def through_ms(
        self,
        t_ms: int,
        next_decision_step: int,
        gap_may_hold: Callable[[int], bool],
        duration_over: Callable[[int], bool] | None,
    ) -> int | None:
        """The last tick a setpoint sent at tick ``t_ms`` answers for (None: only its own): before
        ``next_decision_step``, within ``max_grant_ms``, and through no tick at which ``gap_may_hold`` (the gap hold
        could fire there) and up to the tick at which ``duration_over`` (None: the flight has no duration)."""
        if not self.enabled:
            return None
        last_ms = granted_through_ms(t_ms, self.dt_ms, next_decision_step * self.dt_ms, self.max_grant_ms)
        if last_ms is None or (self.fixes_every_tick and duration_over is None):
            return last_ms
        if duration_over is not None and duration_over(t_ms):
            return None  # this tick's answer is the flight's last
        granted_ms = t_ms
        for tick_ms in range(t_ms + self.dt_ms, last_ms + 1, self.dt_ms):
            if not self.fixes_every_tick and gap_may_hold(tick_ms):
                break  # the gap hold could fire here if no fix comes
            granted_ms = tick_ms
            if duration_over is not None and duration_over(tick_ms):
                break  # the flight ends with this tick's answer
        return granted_ms if granted_ms > t_ms else None
