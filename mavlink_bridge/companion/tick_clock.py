"""The vehicle's clock as a companion follows it: the newest tick its telemetry stamped and when it was read, the
newest position fix's, the last tick controlled, and from these when the next control step is due and how long the
companion may wait for a frame.

Each control step is one new tick of the vehicle's clock (``time_boot_ms``), never of the wall clock. A known tick
waits up to ``settle_s`` wall seconds for its fix, off lockstep (under lockstep the vehicle sends a step's telemetry
in one datagram and then waits for us, so a fix that is not there was lost by the link), and under lockstep only the
step's tick (SYSTEM_TIME, sent after the rest of the step) says a step is there. Off lockstep the vehicle's clock is
extrapolated at its measured rate (:class:`~mavlink_bridge.companion.clock_rate.ClockRate`) while no frame comes.
"""

from __future__ import annotations

from dataclasses import dataclass

from mavlink_bridge.companion.clock_rate import ClockRate

TIMED_TYPES = frozenset({"ATTITUDE", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "SYSTEM_TIME", "NAMED_VALUE_INT"})
"""Messages whose ``time_boot_ms`` is the vehicle's clock."""
WAIT_S = 0.1
"""The longest a receive blocks when no tick is due (wall seconds)."""


@dataclass(frozen=True)
class DueTick:
    """A control step that is due now."""

    t_ms: int
    """The vehicle tick it controls."""
    trigger_rx_s: float | None
    """Wall time the frame that made it due was read (its latency is measured from there); None if extrapolated."""
    extrapolated: bool
    """No frame told the tick: the vehicle's clock was extrapolated at its rate."""


class TickClock:
    """One flight's view of the vehicle's clock (see the module docstring); a new one after a vehicle restart."""

    def __init__(self, dt_ms: int, lockstep: bool, settle_s: float) -> None:
        self.dt_ms = dt_ms
        self.lockstep = lockstep
        self.settle_s = 0.0 if lockstep else settle_s
        """How long a known tick waits for its fix (wall seconds)."""
        self.vt_ms: int | None = None
        """The newest vehicle time seen."""
        self.vt_rx_s = 0.0
        """Wall time it was first seen."""
        self.fix_ms: int | None = None
        """The time of the newest position fix."""
        self.fix_rx_s = 0.0
        self.last_control_ms: int | None = None
        """The last tick controlled (None: act at once on the newest tick)."""
        self._rate = ClockRate()

    @property
    def rate(self) -> float | None:
        """Vehicle seconds per wall second (:class:`ClockRate`), None until measured."""
        return self._rate.rate

    def stamps_time(self, mtype: str) -> bool:
        """A frame of type ``mtype`` tells the vehicle's time: any timed one off lockstep; under lockstep only the
        step's tick (a frame of a step read before its tick may have come without the step's fix, the rest in a
        datagram not yet read)."""
        return mtype in TIMED_TYPES and (mtype == "SYSTEM_TIME" or not self.lockstep)

    def went_back(self, t_ms: int, restart_jump_s: float) -> bool:
        """Vehicle time ``t_ms`` is more than ``restart_jump_s`` before the newest seen: the vehicle restarted."""
        return self.vt_ms is not None and t_ms < self.vt_ms - restart_jump_s * 1000.0

    def seen(self, t_ms: int, rx_s: float) -> None:
        """Vehicle time ``t_ms``, read at wall time ``rx_s``."""
        if self.vt_ms is None or t_ms > self.vt_ms:
            self.vt_ms = t_ms
            self.vt_rx_s = rx_s
            self._rate.seen(rx_s, t_ms)

    def fix(self, t_ms: int, rx_s: float) -> None:
        """A position fix of vehicle time ``t_ms``, read at ``rx_s``."""
        if self.fix_ms is None or t_ms >= self.fix_ms:
            self.fix_ms = t_ms
            self.fix_rx_s = rx_s

    def tick_due(self) -> bool:
        """A vehicle tick newer than the last control step is known."""
        if self.vt_ms is None:
            return False
        return self.last_control_ms is None or self.vt_ms >= self.last_control_ms + self.dt_ms - 1

    def later_tick_read(self, t_ms: int) -> bool:
        """Under lockstep a frame of time ``t_ms``, a later tick's, is read while a tick is due: the due tick is
        controlled first (a lockstep world sends ticks back to back through a grant and after the mission's end, its
        linger: each is controlled before anything of a later one is read, as if the world had waited for its
        answer, however fast the next ticks come)."""
        return self.lockstep and self.tick_due() and t_ms > (self.vt_ms or 0)

    def extrapolating(self) -> bool:
        """Off lockstep, once the clock's rate is measured: the vehicle's time goes on between frames."""
        return not self.lockstep and self.rate is not None and self.rate > 0 and self.vt_ms is not None

    def due(self, now: float, last_rx_s: float) -> DueTick | None:
        """The control step due at wall time ``now`` (the last frame from the vehicle read at ``last_rx_s``): the
        newest tick once its fix came (or its settling time is over); off lockstep, with the vehicle silent for
        1.5 ticks, the tick extrapolated at the clock's rate. None: nothing is due."""
        if self.vt_ms is None:
            return None
        if self.tick_due():
            if self.fix_ms != self.vt_ms and now < self.vt_rx_s + self.settle_s:
                return None  # the tick's fix is probably still on its way
            trigger = self.fix_rx_s if self.fix_ms == self.vt_ms else self.vt_rx_s
            return DueTick(self.vt_ms, trigger, extrapolated=False)
        if self.extrapolating():
            assert self.rate is not None and self.last_control_ms is not None
            silent_s = now - last_rx_s
            if silent_s < 1.5 * self.dt_ms / 1000.0 / self.rate:
                return None
            est_ms = self.vt_ms + (now - self.vt_rx_s) * self.rate * 1000.0
            tick_ms = int(est_ms // self.dt_ms) * self.dt_ms
            if tick_ms >= self.last_control_ms + self.dt_ms:
                return DueTick(tick_ms, None, extrapolated=True)
        return None

    def controlled(self, t_ms: int) -> int:
        """Tick ``t_ms`` is controlled now; the ticks skipped since the last control step."""
        skipped = 0
        if self.last_control_ms is not None and t_ms > self.last_control_ms + self.dt_ms:
            skipped = (t_ms - self.last_control_ms) // self.dt_ms - 1
        self.last_control_ms = t_ms
        return skipped

    def wait_s(self, flying: bool, now: float) -> float:
        """How long the next receive may block at wall time ``now`` (``flying``: the companion controls the vehicle):
        not at all when a tick is due and its fix is there, until its settling time is over when the fix is not, half
        a tick of the vehicle's clock while it is extrapolated, else :data:`WAIT_S`."""
        wait = WAIT_S
        if flying and self.vt_ms is not None and self.tick_due():
            if self.fix_ms != self.vt_ms:
                wait = max(0.0, self.vt_rx_s + self.settle_s - now)
            else:
                wait = 0.0
        elif flying and self.extrapolating() and self.rate:
            wait = min(wait, 0.5 * self.dt_ms / 1000.0 / self.rate)
        return wait
