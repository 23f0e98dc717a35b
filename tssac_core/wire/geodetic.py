"""Frames and the flat-earth conversion between the world's metres and geodetic coordinates.

The world (:mod:`tssac_core.sim.world`) works in x east, y north (metres from the area's south-west
corner) with heading phi counter-clockwise from east (eq. 5). MAVLink speaks NED (x north, y east,
z down), yaw clockwise from north, and latitude/longitude in degrees. The projection and the headings
that cross that boundary go through this module, on both sides: the SITL vehicles
(:mod:`sim_vehicles.autopilot.telemetry`) and the companion (:mod:`mavlink_bridge.link.frames`); the units of the fields
(degE7, cm/s, ms, ...) and the NED axes and signs are :mod:`tssac_core.wire.units`.

Flat earth (an equirectangular projection about the scenario's ``origin``)::

    lat = lat0 + degrees(north_m / R)
    lon = lon0 + degrees(east_m / (R cos(lat0)))

with R = 6 378 100 m, the radius behind ArduPilot's ``LOCATION_SCALING_FACTOR``, and the longitude
scale taken at the *origin's* latitude so the two directions invert exactly. Over the 100 km area
this differs from a geodesic by well under 0.1 %; clients that need metres should read
LOCAL_POSITION_NED, which is exact.
"""

from __future__ import annotations

import math
from typing import Protocol


class Origin(Protocol):
    """Where the area's south-west corner is (a scenario's ``origin``, :class:`tssac_core.sim.scenario.Origin`)."""

    @property
    def lat_deg(self) -> float: ...

    @property
    def lon_deg(self) -> float: ...


EARTH_RADIUS_M = 6_378_100.0
"""Sphere radius of the flat-earth conversion (ArduPilot's LOCATION_SCALING_FACTOR * 1e7 * 180 / pi)."""


def local_to_geodetic(origin: Origin, east_m: float, north_m: float) -> tuple[float, float]:
    """(lat_deg, lon_deg) of a point ``east_m``/``north_m`` metres from the origin."""
    lat = origin.lat_deg + math.degrees(north_m / EARTH_RADIUS_M)
    lon = origin.lon_deg + math.degrees(east_m / (EARTH_RADIUS_M * math.cos(math.radians(origin.lat_deg))))
    lon = (lon + 180.0) % 360.0 - 180.0
    return lat, lon


def geodetic_to_local(origin: Origin, lat_deg: float, lon_deg: float) -> tuple[float, float]:
    """(east_m, north_m) of a geodetic point; the exact inverse of :func:`local_to_geodetic`."""
    d_lon = (lon_deg - origin.lon_deg + 180.0) % 360.0 - 180.0
    east = math.radians(d_lon) * EARTH_RADIUS_M * math.cos(math.radians(origin.lat_deg))
    north = math.radians(lat_deg - origin.lat_deg) * EARTH_RADIUS_M
    return east, north


def wrap_pi(angle_rad: float) -> float:
    """Wrap to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def yaw_ned_from_phi(phi_rad: float) -> float:
    """MAVLink yaw (rad, clockwise from north, [-pi, pi)) of the world's heading phi (CCW from east)."""
    return wrap_pi(math.pi / 2.0 - phi_rad)


def phi_from_yaw_ned(yaw_rad: float) -> float:
    """The world's heading phi (CCW from east) of a MAVLink yaw (clockwise from north)."""
    return wrap_pi(math.pi / 2.0 - yaw_rad)


def heading_cdeg(phi_rad: float) -> int:
    """Heading as MAVLink's centidegrees in [0, 36000) (GLOBAL_POSITION_INT.hdg, GPS_RAW_INT.cog)."""
    return int(round(math.degrees(yaw_ned_from_phi(phi_rad)) * 100.0)) % 36000
