"""The lockstep grant: a companion that knows its setpoint will not change lets the world step on without it.

Under ``--lockstep`` the SITL world takes a step once every vehicle in the loop has answered the newest tick
(SYSTEM_TIME) with a setpoint stamped with that tick's ``time_boot_ms``. A companion whose pilot holds each action
for k ticks would answer k times with the same setpoint, and every answer costs a round of wake-ups in four
processes. Instead it may send, in the same datagram right after the setpoint, a NAMED_VALUE_INT named
:data:`GRANT_NAME` whose ``value`` is the ``time_boot_ms`` of the last tick that setpoint answers: the world then
counts the ticks up to it as answered, flies the setpoint through them (as it flies any setpoint until the next
one), and waits again at the tick after. The vehicle's flight is the one it would fly with an answer at every tick,
as long as the link loses nothing (an answer lost would have been repeated at the next tick) and the companion
grants only ticks at which it cannot change its mind (:func:`granted_through_ms`).

The world honours a grant only from a client (signed, when signing is on), only beside a setpoint that credited a
tick in the same datagram, and only ahead of that setpoint's stamp; a vehicle that leaves the loop forgets it.
"""

from __future__ import annotations

GRANT_NAME = "LS_GRANT"
"""The NAMED_VALUE_INT name of a lockstep grant (at most 10 characters); ``value``: the last granted tick's
``time_boot_ms``; ``time_boot_ms``: the setpoint's stamp."""


def granted_through_ms(tick_ms: int, dt_ms: int, next_change_tick_ms: int, max_grant_ms: int) -> int | None:
    """The last tick a setpoint sent at ``tick_ms`` may answer for, or None to answer the next tick as usual.

    ``next_change_tick_ms``: the first tick at which the companion may send another setpoint (its pilot's and
    monitor's next decision); ``max_grant_ms``: the longest grant the companion allows itself (kept within the
    vehicle's setpoint timeout). The grant never reaches a tick at which the companion could decide otherwise, so
    the granted ticks would have been answered with this very setpoint; a companion whose telemetry may have gaps
    cuts it further, before the first tick at which a gap could change its mind."""
    last_ms = min(next_change_tick_ms - dt_ms, tick_ms + max_grant_ms)
    last_ms = tick_ms + (last_ms - tick_ms) // dt_ms * dt_ms  # on the tick grid
    return last_ms if last_ms > tick_ms else None
