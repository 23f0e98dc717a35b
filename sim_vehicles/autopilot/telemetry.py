"""Telemetry messages built from a vehicle's state: pure functions, units and frames stated.

Inputs are in the world's frame (x east, y north in metres from the area's south-west corner, heading
phi CCW from east, turn rate omega CCW-positive); outputs follow the MAVLink message definitions
(NED, yaw clockwise from north, degE7, mm, cm/s, centidegrees), converted by :mod:`tssac_core.wire.units` and
:mod:`tssac_core.wire.geodetic`, which the companion reads them back with. Altitude is constant: the flight
altitude ``origin.alt_m`` above mean sea level. Home is the vehicle's start position at sea level,
so ``relative_alt`` (height above home) equals ``alt`` as well.

The LOCAL_POSITION_NED origin is the scenario's origin (the area's SW corner) at the flight altitude:
``x = north_m``, ``y = east_m``, ``z = 0`` — the world's coordinates exactly, with the axes swapped.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TypeAlias

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sim_vehicles.link.link_model import GpsFix
from tssac_core.sim.scenario import Origin
from tssac_core.wire import units
from tssac_core.wire.geodetic import heading_cdeg, local_to_geodetic, yaw_ned_from_phi

_log = logging.getLogger(__name__)

GRAVITY_M_S2 = 9.80665
UINT16_MAX = 65535
SATELLITES = 12
"""GPS_RAW_INT.satellites_visible while the receiver has a fix."""
HDOP_X100 = 100
"""GPS_RAW_INT.eph: a nominal HDOP of 1.0 (the noise model has no geometry)."""

MAV: TypeAlias = mavlink2.MAVLink
Msg: TypeAlias = mavlink2.MAVLink_message


@dataclass(frozen=True)
class AirData:
    """What the airframe does in the air, when the dynamics model it (JSBSim; the kinematic model in wind)."""

    airspeed_m_s: float
    """True airspeed."""
    heading_rad: float
    """Where the nose points, CCW from east (the world's frame; ATTITUDE's yaw is pi/2 minus it)."""
    roll_rad: float
    """Bank, right wing down positive (MAVLink's ATTITUDE)."""
    pitch_rad: float
    """Nose up positive."""
    roll_rate_rad_s: float
    pitch_rate_rad_s: float
    yaw_rate_rad_s: float
    """Body rates p, q, r (forward-right-down axes, as ATTITUDE reports them)."""
    alt_m: float
    """Altitude above mean sea level."""
    climb_m_s: float
    """Up positive."""
    wind_east_m_s: float
    wind_north_m_s: float
    """The air mass's velocity at the vehicle (the world's frame)."""
    throttle: float
    """0..1."""


@dataclass(frozen=True)
class VehicleTruth:
    """A vehicle's true state after a world step."""

    east_m: float
    north_m: float
    speed_m_s: float
    """Ground speed."""
    phi_rad: float
    """Course over the ground, CCW from east (eq. 5's heading in calm air)."""
    turn_rate_rad_s: float
    """The course's turn rate over the last step, CCW-positive (the kinematic model: omega as flown)."""
    accel_m_s2: float
    """Ground speed change over the last step / dt (after the speed bounds)."""
    air: AirData | None = None
    """The airframe's own state; None in the kinematic model in calm air, where it follows from the path
    (airspeed = ground speed, coordinated-turn bank, the flight altitude)."""

    @property
    def vel_east_m_s(self) -> float:
        return self.speed_m_s * math.cos(self.phi_rad)

    @property
    def vel_north_m_s(self) -> float:
        return self.speed_m_s * math.sin(self.phi_rad)


def _i16(x: float) -> int:
    return max(-32768, min(32767, int(round(x))))


def heartbeat(mav: MAV, armed: bool, custom_mode: int, guided: bool, system_status: int) -> Msg:
    """HEARTBEAT of a fixed-wing vehicle speaking ArduPilot's mode numbers."""
    base_mode = mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if armed:
        base_mode |= mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
    if guided:
        base_mode |= mavlink2.MAV_MODE_FLAG_GUIDED_ENABLED
    return mav.heartbeat_encode(
        mavlink2.MAV_TYPE_FIXED_WING, mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA, base_mode, custom_mode, system_status, 3
    )


def global_position_int(mav: MAV, origin: Origin, fix: GpsFix, truth: VehicleTruth) -> Msg:
    """GLOBAL_POSITION_INT of a GPS fix (time_boot_ms = the fix's time); hdg from the true heading (the nose's, where
    the dynamics model it), altitude the true one (the flight altitude in the kinematic model)."""
    lat, lon = local_to_geodetic(origin, fix.east_m, fix.north_m)
    air = truth.air
    alt_mm = units.mm_from_m(origin.alt_m if air is None else air.alt_m)
    phi_rad = truth.phi_rad if air is None else air.heading_rad
    vx, vy = units.ned_from_world(fix.vel_east_m_s, fix.vel_north_m_s)
    return mav.global_position_int_encode(
        units.ms_from_s(fix.time_s),
        units.deg_e7(lat),
        units.deg_e7(lon),
        alt_mm,
        alt_mm,
        _i16(units.cm_from_m(vx)),
        _i16(units.cm_from_m(vy)),
        0,
        heading_cdeg(phi_rad),
    )


def local_position_ned_fields(fix: GpsFix) -> tuple[int, float, float, float, float, float, float]:
    """LOCAL_POSITION_NED's fields (``local_position_ned_encode``'s arguments) of a GPS fix: x north = world y,
    y east = world x, z 0 (flight altitude)."""
    x, y = units.ned_from_world(fix.east_m, fix.north_m)
    vx, vy = units.ned_from_world(fix.vel_east_m_s, fix.vel_north_m_s)
    return units.ms_from_s(fix.time_s), x, y, 0.0, vx, vy, 0.0


def gps_raw_int(
    mav: MAV,
    origin: Origin,
    fix: GpsFix | None,
    has_fix: bool,
    time_boot_ms: int,
    position_sigma_m: float,
    velocity_sigma_m_s: float,
) -> Msg:
    """GPS_RAW_INT: the latest fix, fix_type 3D while it is fresh, NO_FIX otherwise (time_usec = time since boot)."""
    if fix is None:
        return mav.gps_raw_int_encode(
            units.us_from_ms(time_boot_ms),
            mavlink2.GPS_FIX_TYPE_NO_FIX,
            0,
            0,
            0,
            UINT16_MAX,
            UINT16_MAX,
            UINT16_MAX,
            UINT16_MAX,
            0,
        )
    lat, lon = local_to_geodetic(origin, fix.east_m, fix.north_m)
    speed = math.hypot(fix.vel_east_m_s, fix.vel_north_m_s)
    cog = heading_cdeg(units.course_phi(fix.vel_east_m_s, fix.vel_north_m_s))
    return mav.gps_raw_int_encode(
        units.us_from_ms(time_boot_ms),
        mavlink2.GPS_FIX_TYPE_3D_FIX if has_fix else mavlink2.GPS_FIX_TYPE_NO_FIX,
        units.deg_e7(lat),
        units.deg_e7(lon),
        units.mm_from_m(origin.alt_m),
        HDOP_X100,
        UINT16_MAX,
        min(UINT16_MAX - 1, int(round(units.cm_from_m(speed)))),
        cog,
        SATELLITES if has_fix else 0,
        units.mm_from_m(origin.alt_m),
        units.mm_from_m(position_sigma_m),
        0,
        units.mm_from_m(velocity_sigma_m_s),
        0,
        0,
    )


def attitude(mav: MAV, truth: VehicleTruth, time_boot_ms: int) -> Msg:
    """ATTITUDE: the airframe's own where the dynamics model it; in the kinematic model in calm air yaw = pi/2 - phi
    (wrapped), yawspeed = -omega and roll the coordinated-turn bank angle."""
    air = truth.air
    if air is not None:
        yaw = yaw_ned_from_phi(air.heading_rad)
        return mav.attitude_encode(
            time_boot_ms,
            air.roll_rad,
            air.pitch_rad,
            yaw,
            air.roll_rate_rad_s,
            air.pitch_rate_rad_s,
            air.yaw_rate_rad_s,
        )
    yawspeed = units.yaw_rate_from_omega(truth.turn_rate_rad_s)
    roll = math.atan(truth.speed_m_s * yawspeed / GRAVITY_M_S2)
    return mav.attitude_encode(time_boot_ms, roll, 0.0, yaw_ned_from_phi(truth.phi_rad), 0.0, 0.0, yawspeed)


def vfr_hud(mav: MAV, truth: VehicleTruth, alt_m: float, accel_cmd: float) -> Msg:
    """VFR_HUD: airspeed apart from ground speed, the nose's heading, throttle, altitude and climb where the dynamics
    model them; in the kinematic model in calm air air = ground speed and throttle = 50 + 50 * the acceleration
    command in [-1, 1]."""
    air = truth.air
    if air is not None:
        heading_deg = units.deg_from_cdeg(heading_cdeg(air.heading_rad))
        throttle = units.percent_from_fraction(air.throttle)
        return mav.vfr_hud_encode(air.airspeed_m_s, truth.speed_m_s, heading_deg, throttle, air.alt_m, air.climb_m_s)
    heading_deg = units.deg_from_cdeg(heading_cdeg(truth.phi_rad))
    throttle = int(round(50.0 + 50.0 * max(-1.0, min(1.0, accel_cmd))))
    return mav.vfr_hud_encode(truth.speed_m_s, truth.speed_m_s, heading_deg, throttle, alt_m, 0.0)


def wind(mav: MAV, truth: VehicleTruth) -> Msg | None:
    """ArduPilot's WIND (ardupilotmega): the direction the wind blows from (deg, clockwise from north, 0..360) and its
    speed, as ArduPlane reports its wind estimate; None in calm air or where the dynamics know no air."""
    air = truth.air
    if air is None:
        return None
    speed = math.hypot(air.wind_east_m_s, air.wind_north_m_s)
    if speed == 0.0:
        return None
    from_deg = math.degrees(math.atan2(-air.wind_east_m_s, -air.wind_north_m_s)) % 360.0
    return mav.wind_encode(from_deg, speed, 0.0)


INERTIAL_SENSORS = (
    mavlink2.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mavlink2.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink2.MAV_SYS_STATUS_SENSOR_3D_MAG
)
"""The AHRS's gyro, accelerometer and magnetometer: the attitude is the true one, so they are always healthy."""
SENSORS_PRESENT = (
    INERTIAL_SENSORS
    | mavlink2.MAV_SYS_STATUS_SENSOR_GPS
    | mavlink2.MAV_SYS_STATUS_AHRS
    | mavlink2.MAV_SYS_STATUS_GEOFENCE
    | mavlink2.MAV_SYS_STATUS_PREARM_CHECK
)
"""Gyro, accelerometer, magnetometer and AHRS (true attitude), GPS (the noise model), geofence (the area bounds),
pre-arm check (GPS fix). MAVSDK's ``health_all_ok`` needs the first three and the GPS healthy, and a HOME_POSITION."""


BATTERY_MV = 12_600
"""The battery is not modelled: reported full and constant, at ArduPilot SITL's default SIM_BATT_VOLTAGE (12.6 V).
UINT16_MAX ("not sent", the spec's unknown) is shown as 65.5 V by MAVSDK 4 and MAVProxy 1.8, which do not check it."""
BATTERY_REMAINING_PCT = 100


def sys_status(mav: MAV, gps_ok: bool, fence_ok: bool, errors_comm: int) -> Msg:
    """SYS_STATUS with the sensors we simulate; a full battery (:data:`BATTERY_MV`), its current not measured (-1)."""
    health = mavlink2.MAV_SYS_STATUS_AHRS | INERTIAL_SENSORS
    if gps_ok:
        health |= mavlink2.MAV_SYS_STATUS_SENSOR_GPS | mavlink2.MAV_SYS_STATUS_PREARM_CHECK
    if fence_ok:
        health |= mavlink2.MAV_SYS_STATUS_GEOFENCE
    return mav.sys_status_encode(
        SENSORS_PRESENT,
        SENSORS_PRESENT,
        health,
        0,
        BATTERY_MV,
        -1,
        BATTERY_REMAINING_PCT,
        0,
        min(UINT16_MAX, errors_comm),
        0,
        0,
        0,
        0,
    )


def extended_sys_state(mav: MAV) -> Msg:
    """EXTENDED_SYS_STATE: not a VTOL, always in the air (the vehicles fly from the first step)."""
    return mav.extended_sys_state_encode(mavlink2.MAV_VTOL_STATE_UNDEFINED, mavlink2.MAV_LANDED_STATE_IN_AIR)


def system_time_fields(unix_start_s: float, time_s: float) -> tuple[int, int]:
    """SYSTEM_TIME's fields (``system_time_encode``'s arguments): both clocks follow simulated time (unix time = start
    of the run + simulated time)."""
    return units.us_from_s(unix_start_s + time_s), units.ms_from_s(time_s)


def home_position(mav: MAV, origin: Origin, home_east_m: float, home_north_m: float, time_s: float) -> Msg:
    """HOME_POSITION: the start position at sea level; local x/y/z in the LOCAL_POSITION_NED frame."""
    lat, lon = local_to_geodetic(origin, home_east_m, home_north_m)
    x, y = units.ned_from_world(home_east_m, home_north_m)
    return mav.home_position_encode(
        units.deg_e7(lat),
        units.deg_e7(lon),
        0,
        x,
        y,
        origin.alt_m,
        [1.0, 0.0, 0.0, 0.0],
        0.0,
        0.0,
        0.0,
        units.us_from_s(time_s),
    )


def gps_global_origin(mav: MAV, origin: Origin, time_s: float) -> Msg:
    """GPS_GLOBAL_ORIGIN: the LOCAL_POSITION_NED origin (area's SW corner, flight altitude)."""
    return mav.gps_global_origin_encode(
        units.deg_e7(origin.lat_deg),
        units.deg_e7(origin.lon_deg),
        units.mm_from_m(origin.alt_m),
        units.us_from_s(time_s),
    )


CAPABILITIES = (
    mavlink2.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mavlink2.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mavlink2.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink2.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mavlink2.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
    | mavlink2.MAV_PROTOCOL_CAPABILITY_MISSION_INT
)
"""AUTOPILOT_VERSION.capabilities (MAVLink has no capability bit for signing). MISSION_INT: ground stations
(MAVSDK) refuse to start a mission, fence or rally download without it; the vehicle has none of them
(MISSION_COUNT 0) and refuses uploads. No FTP bit: MAVLink FTP is answered with NAKs."""
SW_VERSION = (0 << 24) | (1 << 16) | (0 << 8) | mavlink2.FIRMWARE_VERSION_TYPE_DEV
"""0.1.0-dev in ArduPilot's (major, minor, patch, type) byte layout."""


def autopilot_version(mav: MAV, sysid: int) -> Msg:
    custom = list(b"tssacsim")
    return mav.autopilot_version_encode(CAPABILITIES, SW_VERSION, 0, 0, 0, custom, [0] * 8, [0] * 8, 0, 0, sysid)


STATUSTEXT_MAX = 50
"""Characters of one STATUSTEXT chunk: every text the vehicle makes fits (tests/test_sim_vehicles.py checks them)."""


def statustext(mav: MAV, severity: int, text: str) -> Msg:
    """STATUSTEXT: one chunk. A longer text (a client's, relayed) is cut, and the cut logged."""
    if len(text) > STATUSTEXT_MAX:
        _log.warning("STATUSTEXT cut to %d characters: %r", STATUSTEXT_MAX, text)
    return mav.statustext_encode(severity, text[:STATUSTEXT_MAX].encode("ascii", "replace"))


def named_value_int(mav: MAV, time_boot_ms: int, name: str, value: int) -> Msg:
    return mav.named_value_int_encode(time_boot_ms, name[:10].encode("ascii"), int(value))
