"""Flight modes: ArduPlane's numbers for the modes these vehicles fly, and why the others are refused.

The HEARTBEAT says fixed wing (MAV_TYPE_FIXED_WING) and ArduPilot (MAV_AUTOPILOT_ARDUPILOTMEGA), so
ground stations read ``custom_mode`` with ArduPlane's table: MAVProxy and pymavlink take the mode names
from ``mavutil.mode_mapping_bynumber(HEARTBEAT.type)`` for every autopilot except PX4 (all 26 ArduPlane
names for a fixed wing, whatever the vehicle can fly), MAVSDK from ``to_flight_mode_from_custom_mode``
(ArduPlane: MANUAL -> Manual, LOITER -> Hold, RTL -> ReturnToLaunch, AUTO -> Mission, GUIDED ->
Guided, which its Python enum lacks and shows as Unknown). Neither can be told a shorter list, so the
list is made true instead: every mode flown here has ArduPlane's number and ArduPlane's meaning, and a
request for any other is refused with MAV_RESULT_DENIED and a STATUSTEXT that says why.

=========  ===  ===========================================================================
mode       num  behaviour here
=========  ===  ===========================================================================
MANUAL       0  hold heading and speed (no stick input: the idle mode the vehicles start in)
CIRCLE       1  a constant turn at the loiter radius, no position control (ArduPlane's CIRCLE)
RTL         11  fly home and circle over it (radius WP_LOITER_RAD, at least what the turn limit allows)
LOITER      12  circle where it is: the circle through the vehicle's position and heading
GUIDED      15  fly the companion's / MAVSDK's setpoints (when armed)
=========  ===  ===========================================================================

The circles are flown clockwise, as ArduPlane does with a positive WP_LOITER_RAD.
"""

from __future__ import annotations

import enum


class FlightMode(enum.IntEnum):
    """custom_mode values (ArduPlane's numbering)."""

    MANUAL = 0
    CIRCLE = 1
    RTL = 11
    LOITER = 12
    GUIDED = 15


AUTONOMOUS = frozenset({FlightMode.CIRCLE, FlightMode.RTL, FlightMode.LOITER})
"""Modes in which the autopilot steers by itself (navigation.py)."""

_REFUSED = {
    2: "STABILIZE",
    3: "TRAINING",
    4: "ACRO",
    5: "FBWA",
    6: "FBWB",
    7: "CRUISE",
    8: "AUTOTUNE",
}
"""ArduPlane's pilot modes: they fly the sticks, and there is no RC input here."""


def refusal(custom_mode: int) -> str:
    """Why ``custom_mode`` is refused (one STATUSTEXT, under 50 characters)."""
    if custom_mode in _REFUSED:
        return f"{_REFUSED[custom_mode]}: no RC here; MANUAL LOITER RTL GUIDED"
    if custom_mode == 10:
        return "AUTO: no mission here; use GUIDED or RTL"
    if 17 <= custom_mode <= 23 or custom_mode == 25:
        return f"Mode {custom_mode}: not a quadplane; use LOITER/RTL"
    if custom_mode == 13:
        return "TAKEOFF: already airborne; use LOITER"
    shown = custom_mode if 0 <= custom_mode < 1_000_000 else "?"
    return f"Mode {shown}: fly MANUAL/CIRCLE/RTL/LOITER/GUIDED"
