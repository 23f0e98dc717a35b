"""MAVLink's units and NED conventions, both ways: the one place the SITL vehicles and the companion convert them.

The world (:mod:`tssac_core.sim.world`, eq. 5) works in seconds, metres and radians: x east, y north, heading
phi counter-clockwise from east, turn rate omega counter-clockwise-positive, and an action [omega, u] in [-1, 1]
scaled by the vehicle's limits. MAVLink's fields are in other units (``time_boot_ms``, microseconds, millimetres,
cm/s, degE7, centidegrees) and another frame (NED: x north, y east; yaw and yaw rate clockwise-positive about the
down axis). The SITL (:mod:`sim_vehicles.autopilot.telemetry`, :mod:`sim_vehicles.autopilot.setpoints`,
:mod:`sim_vehicles.autopilot.vehicle`)
writes telemetry and reads setpoints with these functions, the companion (:mod:`mavlink_bridge.link.frames`) reads
telemetry and writes setpoints with the same ones, so each conversion is written once
(``tests/test_architecture.py`` checks that neither side spells a scale itself).

The projection between metres and latitude/longitude, and headings as yaw / centidegrees, are
:mod:`tssac_core.wire.geodetic`. Standard library only.
"""

from __future__ import annotations

import math

MS_PER_S = 1000.0
"""``time_boot_ms`` and other millisecond fields."""
US_PER_S = 1e6
"""Microsecond fields (SYSTEM_TIME.time_unix_usec, intervals, tlog stamps)."""
US_PER_MS = 1000
NS_PER_S = 1e9
"""TIMESYNC's nanoseconds."""
MM_PER_M = 1000.0
"""Altitudes and GPS accuracies in millimetres."""
CM_PER_M = 100.0
"""Velocities in cm/s (GLOBAL_POSITION_INT.vx/vy, GPS_RAW_INT.vel)."""
E7_PER_DEG = 1e7
"""Latitudes and longitudes in degE7."""
DEG_PER_E7 = 1e-7
CDEG_PER_DEG = 100
"""Headings in centidegrees (GLOBAL_POSITION_INT.hdg, GPS_RAW_INT.cog)."""


# ------------------------------------------------------------------------------------ time


def ms_from_s(time_s: float) -> int:
    """Seconds as whole milliseconds (``time_boot_ms``)."""
    return int(round(time_s * MS_PER_S))


def s_from_ms(time_ms: float) -> float:
    """Milliseconds (``time_boot_ms``) as seconds."""
    return time_ms / MS_PER_S


def us_from_s(time_s: float) -> int:
    """Seconds as whole microseconds."""
    return int(round(time_s * US_PER_S))


def s_from_us(time_us: float) -> float:
    """Microseconds as seconds."""
    return time_us / US_PER_S


def us_from_ms(time_ms: int) -> int:
    """Whole milliseconds as microseconds (GPS_RAW_INT.time_usec from a ``time_boot_ms``)."""
    return time_ms * US_PER_MS


def ns_from_s(time_s: float) -> int:
    """Seconds as whole nanoseconds (TIMESYNC)."""
    return int(round(time_s * NS_PER_S))


# ---------------------------------------------------------------------------- length, speed


def mm_from_m(length_m: float) -> int:
    """Metres as whole millimetres."""
    return int(round(length_m * MM_PER_M))


def cm_from_m(value_m: float) -> float:
    """Metres (or m/s) in centimetres (cm/s), unrounded: each field rounds and clips to its own integer type."""
    return value_m * CM_PER_M


def m_from_cm(value_cm: float) -> float:
    """Centimetres (cm/s) as metres (m/s)."""
    return value_cm / CM_PER_M


# ----------------------------------------------------------------------------------- angles


def deg_e7(deg: float) -> int:
    """Degrees as MAVLink's int32 degE7."""
    return int(round(deg * E7_PER_DEG))


def deg_from_e7(value_e7: float) -> float:
    """degE7 as degrees."""
    return value_e7 * DEG_PER_E7


def deg_from_cdeg(value_cdeg: int) -> int:
    """Whole degrees of a centidegree value (VFR_HUD.heading from a heading in centidegrees)."""
    return value_cdeg // CDEG_PER_DEG


# ------------------------------------------------------------------------------- NED frame


def percent_from_fraction(fraction: float) -> int:
    """A fraction in [0, 1] as a whole percentage (VFR_HUD's throttle), clipped to 0-100."""
    return int(round(100.0 * max(0.0, min(1.0, fraction))))


def ned_from_world(east: float, north: float) -> tuple[float, float]:
    """A horizontal position or velocity in the world's (east, north) as NED's (x north, y east)."""
    return north, east


def world_from_ned(x_north: float, y_east: float) -> tuple[float, float]:
    """NED's (x north, y east) as the world's (east, north)."""
    return y_east, x_north


def course_phi(east: float, north: float) -> float:
    """The world heading (CCW from east, rad) a horizontal velocity points along."""
    return math.atan2(north, east)


def yaw_rate_from_omega(omega_rad_s: float) -> float:
    """NED yaw rate (clockwise-positive) of the world's turn rate omega (counter-clockwise-positive)."""
    return -omega_rad_s


def omega_from_yaw_rate(yaw_rate_rad_s: float) -> float:
    """The world's turn rate omega (counter-clockwise-positive) of an NED yaw rate (clockwise-positive)."""
    return -yaw_rate_rad_s


# -------------------------------------------------------------------------------- the action


def command_from_action(
    omega_n: float, u_n: float, turn_rate_max_rad_s: float, accel_max_m_s2: float
) -> tuple[float, float]:
    """The action [omega, u] in [-1, 1] as (omega rad/s, forward acceleration m/s^2) at the vehicle's limits."""
    return omega_n * turn_rate_max_rad_s, u_n * accel_max_m_s2


def action_from_command(
    omega_rad_s: float, accel_m_s2: float, turn_rate_max_rad_s: float, accel_max_m_s2: float
) -> tuple[float, float]:
    """(omega rad/s, forward acceleration m/s^2) as the action [omega, u] (in [-1, 1] within the limits)."""
    return omega_rad_s / turn_rate_max_rad_s, accel_m_s2 / accel_max_m_s2
