"""The autopilot's own guidance for the modes that fly without a companion: LOITER, CIRCLE and RTL.

Pure functions in the world's frame (x east, y north in metres, heading ``phi`` counter-clockwise from
east, turn rate ``omega`` counter-clockwise-positive, as in eq. 5); they return the turn-rate command in
rad/s, clipped to the vehicle's limit. Speed is held in these modes (acceleration 0).

Orbit following is the vector field of Nelson et al. (2007) / Beard & McLain, "Small Unmanned
Aircraft" (2012), section 10.2: at distance ``d`` from the centre, at bearing ``gamma`` from it, the
commanded course is ``gamma + lam (pi/2 + atan(k (d - R) / R))`` (``lam`` = +1 counter-clockwise here),
which points at the centre from far away, along the circle on it, and outwards inside it; the turn
command is the feed-forward ``lam v / R`` near the circle plus a proportional course correction. From
any distance the vehicle therefore flies towards the centre and settles on the circle: RTL is an orbit
around home, LOITER an orbit around a centre chosen so the vehicle is already on it.

A fixed wing cannot fly a circle tighter than ``v / omega_max`` (250 m/s at 5 deg/s: 2.9 km), so the
radius flown is ``max(WP_LOITER_RAD, v / (ORBIT_RATE_FRACTION omega_max))``: the margin leaves turn
authority for the correction.
"""

from __future__ import annotations

import math

from tssac_core.wire.geodetic import wrap_pi

ORBIT_RATE_FRACTION = 0.8
"""The steady turn of an orbit uses at most this fraction of the turn-rate limit."""
ORBIT_GAIN = 2.0
"""k of the vector field: how sharply the course converges onto the circle (per radius)."""
COURSE_TIME_CONSTANT_S = 2.0
"""Course errors are corrected at error / this (rad/s) before the limit."""


def orbit_radius_m(requested_m: float, speed_m_s: float, turn_rate_max_rad_s: float) -> float:
    """The radius actually flown: the requested one, or the tightest circle the vehicle holds with margin."""
    return max(requested_m, speed_m_s / (ORBIT_RATE_FRACTION * turn_rate_max_rad_s))


def orbit_center(east_m: float, north_m: float, phi_rad: float, radius_m: float, ccw: bool) -> tuple[float, float]:
    """The centre of the circle of ``radius_m`` that passes through the vehicle along its heading."""
    side = phi_rad + (math.pi / 2.0 if ccw else -math.pi / 2.0)  # the centre is to the left for a CCW circle
    return east_m + radius_m * math.cos(side), north_m + radius_m * math.sin(side)


def orbit_turn_rate(
    east_m: float,
    north_m: float,
    phi_rad: float,
    speed_m_s: float,
    center: tuple[float, float],
    radius_m: float,
    ccw: bool,
    turn_rate_max_rad_s: float,
) -> float:
    """omega (CCW-positive, rad/s) that brings the vehicle onto the circle and keeps it there."""
    lam = 1.0 if ccw else -1.0
    de, dn = east_m - center[0], north_m - center[1]
    d = math.hypot(de, dn)
    gamma = math.atan2(dn, de)  # bearing of the vehicle from the centre, CCW from east
    course = gamma + lam * (math.pi / 2.0 + math.atan(ORBIT_GAIN * (d - radius_m) / radius_m))
    error = wrap_pi(course - phi_rad)
    near = max(0.0, 1.0 - abs(d - radius_m) / radius_m)  # feed-forward only close to the circle
    omega = lam * near * speed_m_s / radius_m + error / COURSE_TIME_CONSTANT_S
    return max(-turn_rate_max_rad_s, min(turn_rate_max_rad_s, omega))


def circle_turn_rate(speed_m_s: float, radius_m: float, ccw: bool, turn_rate_max_rad_s: float) -> float:
    """ArduPlane's CIRCLE: a constant turn of ``radius_m`` without position control (it drifts with the wind)."""
    omega = speed_m_s / radius_m
    return min(turn_rate_max_rad_s, omega) * (1.0 if ccw else -1.0)


def course_turn_rate(phi_rad: float, course_rad: float, turn_rate_max_rad_s: float) -> float:
    """omega (CCW-positive) that turns the heading onto ``course_rad`` (CCW from east)."""
    omega = wrap_pi(course_rad - phi_rad) / COURSE_TIME_CONSTANT_S
    return max(-turn_rate_max_rad_s, min(turn_rate_max_rad_s, omega))
