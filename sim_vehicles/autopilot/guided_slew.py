"""ArduPlane's GUIDED slew commands, as the vehicle flies them: MAV_CMD_GUIDED_CHANGE_HEADING (43002) and
MAV_CMD_GUIDED_CHANGE_SPEED (43000), and MAV_CMD_GUIDED_CHANGE_ALTITUDE (43001) answered for a level flight.

What ArduPlane does (``ArduPlane/GCS_MAVLink_Plane.cpp``, ``handle_command_int_guided_slew_commands``, and
``mode_guided.cpp``; read for the semantics, none of it copied):

* every one is accepted only in GUIDED (M.MAV_RESULT_FAILED elsewhere), and a mode change forgets them;
* CHANGE_HEADING: param1 the heading type (0 course over ground, 1 the nose's heading, 2 back to GUIDED's own
  navigation), param2 the target in degrees, clockwise from north, in [0, 360) (DENIED outside), param3 the largest
  centripetal acceleration toward it (m/s^2, at least 0.05). The vehicle banks ``GUIDED_P`` (50 deg of bank per
  radian of heading error) toward the target, the bank limited to atan(param3 / g): a turn of at most param3 / V,
  so a target far enough ahead is a turn at exactly that rate, and a near-zero acceleration is straight flight;
* CHANGE_SPEED: param1 the speed type (only 0, airspeed: DENIED otherwise), param2 the target (FAILED outside the
  airspeed limits), param3 the acceleration to slew at (0: at once). The speed then moves toward the target at that
  rate (within the vehicle's own limit).

Pure functions of the vehicle's state; the world's frame (CCW from east, omega CCW-positive) inside, MAVLink's
(clockwise from north) only in :func:`course_from_heading_deg`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from tssac_core.wire.geodetic import wrap_pi

M = mavlink2

GRAVITY_M_S2 = 9.80665
GUIDED_P_DEG_PER_RAD = 50.0
"""ArduPlane's guided heading controller: 5000 centidegrees of bank per radian of heading error (P only)."""
LEVEL_TOLERANCE_M = 1.0
"""A CHANGE_ALTITUDE within this of the flight altitude asks for nothing new (the vehicles fly level)."""
MIN_CENTRIPETAL_M_S2 = 0.05
"""ArduPlane raises a smaller CHANGE_HEADING acceleration to this."""
HEADING_TYPE_COG = M.HEADING_TYPE_COURSE_OVER_GROUND
HEADING_TYPE_HEADING = M.HEADING_TYPE_HEADING
HEADING_TYPE_DEFAULT = M.HEADING_TYPE_DEFAULT
"""CHANGE_HEADING's param1 (the ardupilotmega dialect's HEADING_TYPE): steer the course, the nose, or neither."""
SPEED_TYPE_AIRSPEED = M.SPEED_TYPE_AIRSPEED
"""CHANGE_SPEED's param1: the only speed type ArduPlane flies."""
SLEW_COMMANDS = frozenset({M.MAV_CMD_GUIDED_CHANGE_SPEED, M.MAV_CMD_GUIDED_CHANGE_HEADING})
"""The two commands a companion flies GUIDED with in the ArduPlane dialect."""


@dataclass(frozen=True)
class HeadingTarget:
    """A CHANGE_HEADING in force."""

    course_rad: float
    """The target, CCW from east (the world's frame)."""
    over_ground: bool
    """True: the course over the ground is steered onto it; False: the nose's heading."""
    centripetal_m_s2: float
    """The largest centripetal acceleration of the turn toward it."""


@dataclass(frozen=True)
class SpeedTarget:
    """A CHANGE_SPEED in force."""

    speed_m_s: float
    """The target airspeed."""
    accel_m_s2: float
    """The rate it is approached at (inf: at once, the vehicle's own limit)."""


def course_from_heading_deg(heading_deg: float) -> float:
    """A MAVLink heading (degrees clockwise from north) as the world's course (radians CCW from east)."""
    return wrap_pi(math.pi / 2.0 - math.radians(heading_deg))


def heading_turn_rate(target: HeadingTarget, now_rad: float, speed_m_s: float, turn_rate_max_rad_s: float) -> float:
    """omega (CCW-positive) toward ``target`` from ``now_rad`` (the course or heading it steers): the bank GUIDED_P
    asks for, limited to atan(a / g), flown as the coordinated turn g tan(bank) / V, within the vehicle's limit."""
    bank_limit = math.atan(target.centripetal_m_s2 / GRAVITY_M_S2)
    error = wrap_pi(target.course_rad - now_rad)
    bank = max(-bank_limit, min(bank_limit, math.radians(GUIDED_P_DEG_PER_RAD) * error))
    omega = GRAVITY_M_S2 * math.tan(bank) / max(speed_m_s, 1.0)
    return max(-turn_rate_max_rad_s, min(turn_rate_max_rad_s, omega))


def speed_accel(target: SpeedTarget, speed_m_s: float, accel_max_m_s2: float, dt_s: float) -> float:
    """The forward acceleration that moves the speed toward ``target`` over the next step: at the target's rate
    (capped by the vehicle's), and dead-beat once within one step of it."""
    rate = min(target.accel_m_s2, accel_max_m_s2)
    return max(-rate, min(rate, (target.speed_m_s - speed_m_s) / dt_s))


@dataclass(frozen=True)
class SlewRefusal:
    """Why a slew command is not flown: its COMMAND_ACK result, and (for a STATUSTEXT) what is wrong."""

    result: int
    text: str


def parse_change_heading(params: tuple[float, ...]) -> HeadingTarget | None | SlewRefusal:
    """CHANGE_HEADING's params -> the target to fly, None (param1 2: back to GUIDED's own navigation), or a refusal."""
    kind, heading_deg, accel = params[0], params[1], params[2]
    if not all(map(math.isfinite, (kind, heading_deg, accel))):
        return SlewRefusal(M.MAV_RESULT_DENIED, "Heading cmd: params not finite")
    if not 0.0 <= heading_deg < 360.0:
        return SlewRefusal(M.MAV_RESULT_DENIED, "Heading cmd: param2 not in [0, 360)")
    if round(kind) == HEADING_TYPE_DEFAULT:
        return None
    if round(kind) not in (HEADING_TYPE_COG, HEADING_TYPE_HEADING):
        return SlewRefusal(M.MAV_RESULT_DENIED, "Heading cmd: param1 not 0 (COG) or 1")
    return HeadingTarget(
        course_rad=course_from_heading_deg(heading_deg),
        over_ground=round(kind) == HEADING_TYPE_COG,
        centripetal_m_s2=max(abs(accel), MIN_CENTRIPETAL_M_S2),
    )


def parse_change_speed(
    params: tuple[float, ...], speed_min_m_s: float, speed_max_m_s: float
) -> SpeedTarget | SlewRefusal:
    """CHANGE_SPEED's params -> the target to fly, or a refusal (an airspeed outside the vehicle's limits: FAILED)."""
    kind, speed, accel = params[0], params[1], params[2]
    if not all(map(math.isfinite, (kind, speed, accel))):
        return SlewRefusal(M.MAV_RESULT_DENIED, "Speed cmd: params not finite")
    if round(kind) != SPEED_TYPE_AIRSPEED:
        return SlewRefusal(M.MAV_RESULT_DENIED, "Speed cmd: only param1 0 (airspeed)")
    if not speed_min_m_s <= speed <= speed_max_m_s:
        return SlewRefusal(
            M.MAV_RESULT_FAILED, f"Speed cmd: {speed:.0f} outside {speed_min_m_s:.0f}-{speed_max_m_s:.0f}"
        )
    return SpeedTarget(speed_m_s=speed, accel_m_s2=math.inf if accel == 0.0 else abs(accel))
