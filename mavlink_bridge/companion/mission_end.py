"""The end of a mission as a companion learns it, and when it believes it.

The vehicle tells a mission's end by NAMED_VALUE_INT (HIT, MSN_END) or their STATUSTEXT; without signing anyone who
can spoof the vehicle's address can send those. So an end heard is only a claim: the companion flies on until the
vehicle's own telemetry confirms it (the vehicle, once its mission has ended, reports POWEROFF in every HEARTBEAT and
falls silent when it exits), and a claim the vehicle's heartbeats go on contradicting is refuted. With signing the
claim came in a frame signed with the run's key, from the vehicle itself: it is believed at once.
"""

from __future__ import annotations

from dataclasses import dataclass

from mavlink_bridge.companion.config import END_CONFIRM_S, END_GRACE_S, END_SILENCE_S
from mavlink_bridge.link.connection import M


@dataclass
class ClaimedEnd:
    """A mission end heard from the vehicle's address, not yet confirmed by the vehicle's own heartbeats."""

    status: str
    message: str
    since_s: float
    """Wall time (time.monotonic()) it was heard."""
    poweroff_since_s: float | None = None
    """When the first POWEROFF heartbeat came after it."""


class EndWatch:
    """The claimed end of the current mission, if any, and whether the vehicle has confirmed or refuted it."""

    def __init__(self) -> None:
        self.claim: ClaimedEnd | None = None

    def hear(self, status: str, message: str, now_s: float) -> bool:
        """An end heard at ``now_s``; True if it is the first claim (a later one changes nothing)."""
        if self.claim is not None:
            return False
        self.claim = ClaimedEnd(status, message, now_s)
        return True

    def heartbeat(self, system_status: int, rx_s: float) -> ClaimedEnd | None:
        """A vehicle heartbeat read at ``rx_s``: POWEROFF confirms the claim; any other state after the grace refutes
        it, and the refuted claim comes back (None: nothing refuted)."""
        claim = self.claim
        if claim is None or rx_s < claim.since_s:
            return None
        if system_status == M.MAV_STATE_POWEROFF:
            if claim.poweroff_since_s is None:
                claim.poweroff_since_s = rx_s
            return None
        if rx_s - claim.since_s <= END_GRACE_S:
            return None
        self.claim = None
        return claim

    def confirmed(self, now_s: float, last_rx_s: float, signed: bool) -> ClaimedEnd | None:
        """The claim, once it is confirmed at ``now_s``: at once when ``signed``, else when the vehicle has been silent
        since it (nothing read after ``last_rx_s``) or has reported only POWEROFF for a while."""
        claim = self.claim
        if claim is None:
            return None
        if signed:
            return claim
        silent = now_s - max(last_rx_s, claim.since_s) >= END_SILENCE_S
        powered_off = claim.poweroff_since_s is not None and now_s - claim.since_s >= END_CONFIRM_S
        return claim if silent or powered_off else None
