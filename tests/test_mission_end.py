"""The companion's belief in a mission's end (mavlink_bridge.companion.mission_end): a claim heard from the vehicle's
address is confirmed by the vehicle's POWEROFF heartbeats or its silence, refuted by any other state after the grace,
and believed at once when it came signed."""

from __future__ import annotations

from mavlink_bridge.companion.config import END_CONFIRM_S, END_GRACE_S, END_SILENCE_S
from mavlink_bridge.companion.mission_end import EndWatch
from mavlink_bridge.link.connection import M

T0 = 100.0


def claimed() -> EndWatch:
    watch = EndWatch()
    assert watch.hear("success", "target hit at 12.0 s", T0)
    return watch


def test_the_first_claim_stands_and_a_later_one_changes_nothing():
    watch = claimed()
    assert not watch.hear("geofence", "mission ended (geofence)", T0 + 1.0)
    assert watch.claim is not None and watch.claim.status == "success"


def test_a_signed_claim_is_believed_at_once():
    watch = claimed()
    assert watch.confirmed(T0, last_rx_s=T0, signed=True) is watch.claim
    assert EndWatch().confirmed(T0, last_rx_s=T0, signed=True) is None  # nothing claimed, nothing believed


def test_poweroff_confirms_only_after_its_time():
    watch = claimed()
    assert watch.heartbeat(M.MAV_STATE_POWEROFF, T0 + 0.1) is None
    still_talking = T0 + END_CONFIRM_S - 0.01
    assert watch.confirmed(still_talking, last_rx_s=still_talking, signed=False) is None
    done = T0 + END_CONFIRM_S
    assert watch.confirmed(done, last_rx_s=done, signed=False) is watch.claim


def test_silence_after_the_claim_confirms_it():
    watch = claimed()
    assert watch.confirmed(T0 + END_SILENCE_S - 0.01, last_rx_s=T0, signed=False) is None
    assert watch.confirmed(T0 + END_SILENCE_S, last_rx_s=T0, signed=False) is watch.claim
    # silence is counted from the later of the claim and the last frame read
    watch = claimed()
    assert watch.confirmed(T0 + END_SILENCE_S, last_rx_s=T0 + 0.2, signed=False) is None


def test_a_vehicle_still_flying_after_the_grace_refutes_the_claim():
    watch = claimed()
    assert watch.heartbeat(M.MAV_STATE_ACTIVE, T0 - 1.0) is None  # read before the claim: says nothing of it
    assert watch.heartbeat(M.MAV_STATE_ACTIVE, T0 + END_GRACE_S) is None  # within the grace
    assert watch.claim is not None
    refuted = watch.heartbeat(M.MAV_STATE_ACTIVE, T0 + END_GRACE_S + 0.01)
    assert refuted is not None and refuted.message == "target hit at 12.0 s"
    assert watch.claim is None and watch.confirmed(T0 + 10.0, last_rx_s=T0, signed=False) is None
    assert watch.hear("geofence", "mission ended (geofence)", T0 + 11.0)  # a new claim may follow
