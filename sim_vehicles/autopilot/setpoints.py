"""Setpoint messages -> what the vehicle flies: pure parsing, no state.

Three forms are understood (all in the body frame, all with a yaw rate):

=====================  ==========================================  =====================================
form                   message, frame, type_mask                   fields used
=====================  ==========================================  =====================================
ACCEL_YAW_RATE         SET_POSITION_TARGET_LOCAL_NED, frame 12     ``afx`` forward acceleration (m/s^2),
(the companion's)      (BODY_FRD) or 8 (BODY_NED), mask 1087        ``yaw_rate`` (rad/s, NED: clockwise +)
                       (+128 / 256: afy / afz ignored; 1471 too)
VELOCITY_YAW_RATE      SET_POSITION_TARGET_LOCAL_NED, frame 8      ``vx`` forward speed (m/s), ``yaw_rate``;
(MAVSDK velocity       or 12, mask 1479 (positions, accelerations   ``vy`` / ``vz`` must be 0 (or ignored:
body + yawspeed)       and yaw ignored; +16 / 32 allowed)           a fixed wing neither slips nor climbs)
THRUST_YAW_RATE        SET_ATTITUDE_TARGET, mask 128 (attitude      ``body_yaw_rate`` (rad/s, clockwise +),
(MAVSDK attitude       ignored; +1 / 2 roll / pitch rates           ``thrust`` in [0, 1]: 0.5 holds speed,
rate)                  ignored)                                     1 / 0 full acceleration / deceleration
VELOCITY_NED           SET_POSITION_TARGET_LOCAL_NED, frame 1      ``vx`` north, ``vy`` east (m/s): the
(MAVSDK velocity       (LOCAL_NED), mask 2503 (positions,           course to fly and its speed; ``vz``
NED + yaw)             accelerations, yaw rate ignored; +1024)      must be 0; ``yaw`` is not used (a fixed
                                                                    wing's heading follows its course)
=====================  ==========================================  =====================================

Anything else is refused with a reason short enough for one STATUSTEXT (under 50 characters) that
says what to send instead.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sim_vehicles.autopilot.guided_slew import HeadingTarget, SpeedTarget
from tssac_core.wire import units

M = mavlink2

BODY_FRAMES = frozenset({M.MAV_FRAME_BODY_FRD, M.MAV_FRAME_BODY_NED})
"""12 (BODY_FRD) and 8 (BODY_NED, which MAVLink defines as body-fixed for velocities and accelerations)."""
_POS = M.POSITION_TARGET_TYPEMASK_X_IGNORE | M.POSITION_TARGET_TYPEMASK_Y_IGNORE | M.POSITION_TARGET_TYPEMASK_Z_IGNORE
_VEL = (
    M.POSITION_TARGET_TYPEMASK_VX_IGNORE | M.POSITION_TARGET_TYPEMASK_VY_IGNORE | M.POSITION_TARGET_TYPEMASK_VZ_IGNORE
)
_ACC = (
    M.POSITION_TARGET_TYPEMASK_AX_IGNORE | M.POSITION_TARGET_TYPEMASK_AY_IGNORE | M.POSITION_TARGET_TYPEMASK_AZ_IGNORE
)
_YAW = M.POSITION_TARGET_TYPEMASK_YAW_IGNORE
ACCEL_MASK = _POS | _VEL | _YAW
"""1087: afx and yaw_rate used (the companion's form)."""
ACCEL_MASK_OPTIONAL = M.POSITION_TARGET_TYPEMASK_AY_IGNORE | M.POSITION_TARGET_TYPEMASK_AZ_IGNORE
VELOCITY_MASK = _POS | _ACC | _YAW
"""1479: vx (vy, vz) and yaw_rate used (MAVSDK's velocity-body form)."""
VELOCITY_MASK_OPTIONAL = M.POSITION_TARGET_TYPEMASK_VY_IGNORE | M.POSITION_TARGET_TYPEMASK_VZ_IGNORE
NED_VELOCITY_MASK = _POS | _ACC | M.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
"""2503: vx north, vy east (vz) used, yaw rate ignored (MAVSDK's velocity-NED form; its yaw is not used)."""
NED_VELOCITY_MASK_OPTIONAL = _YAW
ATTITUDE_MASK = M.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE
"""128: body rates and thrust used, the quaternion ignored."""
ATTITUDE_MASK_OPTIONAL = (
    M.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE | M.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
)
SIDE_SPEED_TOLERANCE_M_S = 0.01
"""|vy|, |vz|, |roll rate|, |pitch rate| up to this are taken as 0."""
STATUSTEXT_MAX = 50


class SetpointForm(enum.Enum):
    ACCEL_YAW_RATE = "accel"
    VELOCITY_YAW_RATE = "velocity"
    THRUST_YAW_RATE = "thrust"
    VELOCITY_NED = "velocity_ned"
    GUIDED_SLEW = "guided_slew"
    """ArduPlane's GUIDED_CHANGE_HEADING / _SPEED (COMMAND_INT or COMMAND_LONG; sim_vehicles.autopilot.guided_slew)."""


@dataclass(frozen=True)
class Demand:
    """What a setpoint asks for, before the vehicle's limits."""

    form: SetpointForm
    yaw_rate_rad_s: float
    """NED, clockwise-positive (0 for VELOCITY_NED, which steers to ``course_rad`` instead)."""
    accel_m_s2: float | None = None
    """Forward acceleration (ACCEL_YAW_RATE)."""
    speed_m_s: float | None = None
    """Forward speed (VELOCITY_YAW_RATE)."""
    thrust: float | None = None
    """[0, 1] (THRUST_YAW_RATE)."""
    course_rad: float | None = None
    """Course to fly, counter-clockwise from east like the world's heading (VELOCITY_NED)."""
    heading_target: HeadingTarget | None = None
    """GUIDED_SLEW: the CHANGE_HEADING in force (None: none, fly straight)."""
    speed_target: SpeedTarget | None = None
    """GUIDED_SLEW: the CHANGE_SPEED in force (None: none, hold the speed)."""


@dataclass(frozen=True)
class Refusal:
    """Why a setpoint is refused, and what to send instead (one STATUSTEXT, < 50 characters)."""

    kind: str
    text: str

    def __post_init__(self) -> None:
        assert len(self.text) < STATUSTEXT_MAX, self.text


def _finite(*values: float) -> bool:
    return all(map(math.isfinite, values))


def parse_position_target(msg: mavlink2.MAVLink_message) -> Demand | Refusal:
    """SET_POSITION_TARGET_LOCAL_NED -> a demand of the ACCEL, VELOCITY or VELOCITY_NED form, or a refusal."""
    mask = msg.type_mask
    if mask & M.POSITION_TARGET_TYPEMASK_FORCE_SET:
        return Refusal("force", "SP force bit 512: clear it")
    if msg.coordinate_frame == M.MAV_FRAME_LOCAL_NED:
        return _parse_ned_velocity(msg)
    if msg.coordinate_frame not in BODY_FRAMES:
        return Refusal("frame", f"SP frame {msg.coordinate_frame}: use 8/12 (body), 1 (NED)")
    if mask & ~ACCEL_MASK_OPTIONAL == ACCEL_MASK:
        if not _finite(msg.afx, msg.yaw_rate):
            return Refusal("finite", "SP afx/yaw_rate not finite: send numbers")
        return Demand(SetpointForm.ACCEL_YAW_RATE, float(msg.yaw_rate), accel_m_s2=float(msg.afx))
    if mask & ~VELOCITY_MASK_OPTIONAL == VELOCITY_MASK:
        if not _finite(msg.vx, msg.yaw_rate):
            return Refusal("finite", "SP vx/yaw_rate not finite: send numbers")
        side = 0.0 if mask & M.POSITION_TARGET_TYPEMASK_VY_IGNORE else msg.vy
        down = 0.0 if mask & M.POSITION_TARGET_TYPEMASK_VZ_IGNORE else msg.vz
        if not (abs(side) <= SIDE_SPEED_TOLERANCE_M_S and abs(down) <= SIDE_SPEED_TOLERANCE_M_S):
            return Refusal("side", "SP vy/vz: fixed wing, send vy = vz = 0")
        return Demand(SetpointForm.VELOCITY_YAW_RATE, float(msg.yaw_rate), speed_m_s=float(msg.vx))
    return Refusal("mask", f"SP mask {mask}: use 1479 (vx) or 1087 (afx)")


def _parse_ned_velocity(msg: mavlink2.MAVLink_message) -> Demand | Refusal:
    if msg.type_mask & ~NED_VELOCITY_MASK_OPTIONAL != NED_VELOCITY_MASK:
        return Refusal("ned_mask", f"SP frame 1 mask {msg.type_mask}: use 2503 (vN, vE)")
    if not _finite(msg.vx, msg.vy, msg.vz):
        return Refusal("finite", "SP vx/vy/vz not finite: send numbers")
    if abs(msg.vz) > SIDE_SPEED_TOLERANCE_M_S:
        return Refusal("side", "SP vz: level flight here, send vz = 0")
    speed = math.hypot(msg.vx, msg.vy)
    if speed <= SIDE_SPEED_TOLERANCE_M_S:
        return Refusal("no_course", "SP vN = vE = 0: a fixed wing needs a course")
    east, north = units.world_from_ned(msg.vx, msg.vy)
    return Demand(SetpointForm.VELOCITY_NED, 0.0, speed_m_s=speed, course_rad=units.course_phi(east, north))


def parse_attitude_target(msg: mavlink2.MAVLink_message) -> Demand | Refusal:
    """SET_ATTITUDE_TARGET -> a THRUST_YAW_RATE demand, or a refusal."""
    mask = msg.type_mask
    if mask & ~ATTITUDE_MASK_OPTIONAL != ATTITUDE_MASK:
        return Refusal("att_mask", f"ATT mask {mask}: use 128 (yaw rate, thrust)")
    roll = 0.0 if mask & M.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE else msg.body_roll_rate
    pitch = 0.0 if mask & M.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE else msg.body_pitch_rate
    if not _finite(roll, pitch, msg.body_yaw_rate, msg.thrust):
        return Refusal("finite", "ATT rates/thrust not finite: send numbers")
    if not (abs(roll) <= SIDE_SPEED_TOLERANCE_M_S and abs(pitch) <= SIDE_SPEED_TOLERANCE_M_S):
        return Refusal("att_rates", "ATT roll/pitch rate: send 0, yaw rate only")
    if not 0.0 <= msg.thrust <= 1.0:
        return Refusal("thrust", "ATT thrust: send 0..1 (0.5 holds speed)")
    return Demand(SetpointForm.THRUST_YAW_RATE, float(msg.body_yaw_rate), thrust=float(msg.thrust))


GLOBAL_REFUSAL = Refusal("global", "Global SP: use local NED, frame 8, mask 1479")
"""SET_POSITION_TARGET_GLOBAL_INT is not flown (no position targets here)."""


def accel_command(
    demand: Demand, speed_m_s: float, accel_max_m_s2: float, speed_min_m_s: float, speed_max_m_s: float, dt_s: float
) -> float:
    """The forward acceleration (m/s^2, within +-accel_max) that flies ``demand`` over the next step.

    ACCEL: afx clipped. VELOCITY: the speed target clipped to the speed bounds, reached as fast as the
    limit allows (dead-beat: one step when it is within accel_max dt). THRUST: (2 thrust - 1) accel_max,
    so 0.5 holds the speed (VFR_HUD reports throttle = 50 + 50 * accel / accel_max, the same scale).
    """
    if demand.form is SetpointForm.ACCEL_YAW_RATE:
        assert demand.accel_m_s2 is not None
        a = demand.accel_m_s2
    elif demand.form in (SetpointForm.VELOCITY_YAW_RATE, SetpointForm.VELOCITY_NED):
        assert demand.speed_m_s is not None
        target = min(speed_max_m_s, max(speed_min_m_s, demand.speed_m_s))
        a = (target - speed_m_s) / dt_s
    else:
        assert demand.thrust is not None
        a = (2.0 * demand.thrust - 1.0) * accel_max_m_s2
    return min(accel_max_m_s2, max(-accel_max_m_s2, a))
