"""Frames and units between MAVLink telemetry / setpoints and the world of :mod:`tssac_core.sim.world`.

World (eq. 5): x east, y north in metres from the area's south-west corner; heading phi
counter-clockwise from east; turn rate omega counter-clockwise-positive; action [omega, u] in
[-1, 1], scaled by the vehicle's limits (``turn_rate_max_deg_s``, ``accel_max_m_s2`` of the scenario).

MAVLink (as the bundled SITL documents it, ``sim_vehicles.autopilot.telemetry`` / ``sim_vehicles.autopilot.vehicle``;
every unit, axis and sign below is converted by :mod:`tssac_core.wire.units`, the functions the SITL uses too):

* LOCAL_POSITION_NED: origin at the area's SW corner, ``x`` north = world y, ``y`` east = world x,
  ``vx`` north, ``vy`` east (m, m/s).
* GLOBAL_POSITION_INT: lat/lon in degE7 from a flat-earth (equirectangular) projection about the
  scenario's ``origin`` with R = 6 378 100 m (ArduPilot's LOCATION_SCALING_FACTOR); ``vx`` north,
  ``vy`` east in cm/s.
* SET_POSITION_TARGET_LOCAL_NED, frame BODY_FRD: ``afx`` forward acceleration (m/s^2) = u;
  ``yaw_rate`` (rad/s) about the down axis, clockwise-positive, so yaw_rate = -omega.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from tssac_core.sim.scenario import Origin, VehicleSpec
from tssac_core.wire import units
from tssac_core.wire.geodetic import geodetic_to_local


class Measurement(NamedTuple):
    """One position/velocity fix in the world frame, stamped with the vehicle's clock (a named tuple: one is made
    per step)."""

    t_s: float
    east_m: float
    north_m: float
    vel_east_m_s: float
    vel_north_m_s: float


def from_local_position_ned(time_boot_ms: int, x_m: float, y_m: float, vx_m_s: float, vy_m_s: float) -> Measurement:
    """LOCAL_POSITION_NED fields -> world measurement (x north -> north, y east -> east)."""
    east, north = units.world_from_ned(x_m, y_m)
    vel_east, vel_north = units.world_from_ned(vx_m_s, vy_m_s)
    return Measurement(units.s_from_ms(time_boot_ms), float(east), float(north), float(vel_east), float(vel_north))


def from_global_position_int(
    origin: Origin, time_boot_ms: int, lat_e7: int, lon_e7: int, vx_cm_s: int, vy_cm_s: int
) -> Measurement:
    """GLOBAL_POSITION_INT fields -> world measurement."""
    east, north = geodetic_to_local(origin, units.deg_from_e7(lat_e7), units.deg_from_e7(lon_e7))
    vel_east, vel_north = units.world_from_ned(units.m_from_cm(vx_cm_s), units.m_from_cm(vy_cm_s))
    return Measurement(units.s_from_ms(time_boot_ms), east, north, vel_east, vel_north)


class Setpoint(NamedTuple):
    """What goes into SET_POSITION_TARGET_LOCAL_NED (BODY_FRD) (a named tuple: one is made per step)."""

    yaw_rate_rad_s: float
    """Clockwise-positive (NED)."""
    accel_m_s2: float
    """Forward."""


HOLD = Setpoint(0.0, 0.0)
"""The safe hold: no turn, no acceleration (fly straight at the current speed)."""


def action_to_setpoint(action: tuple[float, float], spec: VehicleSpec) -> Setpoint:
    """[omega, u] in [-1, 1] (clipped) -> heading rate and forward acceleration at the vehicle's limits."""
    omega_n = min(1.0, max(-1.0, float(action[0])))
    u_n = min(1.0, max(-1.0, float(action[1])))
    omega_rad_s, accel_m_s2 = units.command_from_action(
        omega_n, u_n, math.radians(spec.turn_rate_max_deg_s), spec.accel_max_m_s2
    )
    return Setpoint(yaw_rate_rad_s=units.yaw_rate_from_omega(omega_rad_s), accel_m_s2=accel_m_s2)


def setpoint_to_action(setpoint: Setpoint, spec: VehicleSpec) -> tuple[float, float]:
    """The inverse of :func:`action_to_setpoint`: the [omega, u] a setpoint commands (the monitor's record of
    what the vehicle was sent)."""
    return units.action_from_command(
        units.omega_from_yaw_rate(setpoint.yaw_rate_rad_s),
        setpoint.accel_m_s2,
        math.radians(spec.turn_rate_max_deg_s),
        spec.accel_max_m_s2,
    )
