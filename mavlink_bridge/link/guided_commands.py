"""The two ways a companion commands its vehicle in GUIDED (``--setpoints``), and the ArduPlane form of a setpoint.

* ``body-rates`` (the default): SET_POSITION_TARGET_LOCAL_NED in BODY_FRD, mask 1087: the forward acceleration and
  the yaw rate the policy decided, as the bundled SITL flies them (:mod:`mavlink_bridge.link.frames`).
* ``arduplane``: ArduPlane's own GUIDED commands (ardupilotmega dialect, COMMAND_INT), which a stock ArduPlane flies:
  MAV_CMD_GUIDED_CHANGE_HEADING (43002) with a course target ahead of the current course, on the side of the turn,
  and the centripetal acceleration V |omega| that caps ArduPlane's bank at atan(V |omega| / g), so that it turns at
  omega; and MAV_CMD_GUIDED_CHANGE_SPEED (43000) with the speed limit the acceleration points at and |a| as its
  slew rate (a = 0: the current speed, held).

ArduPlane's guided heading controller banks 50 deg per radian of heading error, up to that cap: a target
:data:`TURN_LEAD_RAD` ahead asks 78 deg, beyond any cap a 5 deg/s turn needs (70 deg at 300 m/s), and stays beyond it
for the whole decision (a turn of 5 deg/s eats 5 deg of it a second). So the turn is flown at the cap, omega, and a
heading command with no turn asks for the current course at the smallest acceleration ArduPlane takes (straight).
"""

from __future__ import annotations

import argparse
import enum
import math
from dataclasses import dataclass

from mavlink_bridge.link.frames import Setpoint
from tssac_core.sim.scenario import VehicleSpec
from tssac_core.wire import units

TURN_LEAD_RAD = math.pi / 2
"""How far ahead of the current course, on the side of the turn, the heading target lies."""
MIN_CENTRIPETAL_M_S2 = 0.05
"""ArduPlane's smallest CHANGE_HEADING acceleration (a smaller one is raised to it): straight flight."""
HOLD_SLEW_M_S2 = 0.01
"""CHANGE_SPEED's rate when the speed is to be held (0 would mean "at once", to a noisy estimate)."""
TURN_EPS_RAD_S = 1e-6
"""A turn rate below this is none."""
MAV_CMD_GUIDED_CHANGE_SPEED, MAV_CMD_GUIDED_CHANGE_HEADING = 43000, 43002
"""The ardupilotmega dialect's command ids (checked against pymavlink's in tests/test_arduplane_dialect.py)."""
SLEW_COMMANDS = frozenset({MAV_CMD_GUIDED_CHANGE_SPEED, MAV_CMD_GUIDED_CHANGE_HEADING})


def compass_deg(course_rad: float) -> float:
    """A course CCW from east as MAVLink's heading: degrees clockwise from north, in [0, 360)."""
    deg = math.degrees(math.pi / 2.0 - course_rad) % 360.0
    return 0.0 if deg >= 360.0 else deg  # -1e-17 % 360 is 360.0


class SetpointDialect(enum.Enum):
    """How the companion's setpoints reach the vehicle (``--setpoints``: :func:`add_setpoints_argument`)."""

    BODY_RATES = "body-rates"
    """SET_POSITION_TARGET_LOCAL_NED, BODY_FRD, mask 1087 (afx, yaw_rate)."""
    ARDUPLANE = "arduplane"
    """ArduPlane's GUIDED_CHANGE_HEADING and GUIDED_CHANGE_SPEED (COMMAND_INT)."""


@dataclass(frozen=True)
class GuidedSlew:
    """One decision as ArduPlane's two GUIDED commands."""

    heading_deg: float | None
    """CHANGE_HEADING's target, degrees clockwise from north in [0, 360), course over ground; None: no estimate of
    the course yet, so HEADING_TYPE_DEFAULT (the autopilot's own GUIDED navigation)."""
    centripetal_m_s2: float
    """CHANGE_HEADING's largest centripetal acceleration (sets the turn rate V omega / V)."""
    speed_m_s: float | None
    """CHANGE_SPEED's target airspeed; None: no speed command (no estimate of the speed yet)."""
    slew_m_s2: float
    """CHANGE_SPEED's rate toward it."""


def slew_from_setpoint(
    setpoint: Setpoint, course_rad: float | None, speed_m_s: float | None, spec: VehicleSpec
) -> GuidedSlew:
    """``setpoint`` (yaw rate, forward acceleration) as ArduPlane's commands, from the estimated course (CCW from
    east) and speed; without an estimate the heading goes back to the autopilot and no speed is commanded."""
    omega = units.omega_from_yaw_rate(setpoint.yaw_rate_rad_s)  # CCW-positive
    heading_deg: float | None = None
    centripetal = MIN_CENTRIPETAL_M_S2
    if course_rad is not None:
        turning = abs(omega) > TURN_EPS_RAD_S
        target = course_rad + (math.copysign(TURN_LEAD_RAD, omega) if turning else 0.0)
        heading_deg = compass_deg(target)
        if turning and speed_m_s is not None:
            centripetal = max(MIN_CENTRIPETAL_M_S2, speed_m_s * abs(omega))
    if speed_m_s is None:
        return GuidedSlew(heading_deg, centripetal, None, 0.0)
    a = setpoint.accel_m_s2
    if a > 0.0:
        return GuidedSlew(heading_deg, centripetal, spec.speed_max_m_s, a)
    if a < 0.0:
        return GuidedSlew(heading_deg, centripetal, spec.speed_min_m_s, -a)
    held = min(spec.speed_max_m_s, max(spec.speed_min_m_s, speed_m_s))
    return GuidedSlew(heading_deg, centripetal, held, HOLD_SLEW_M_S2)


def add_setpoints_argument(parser: argparse._ActionsContainer) -> None:
    """``--setpoints body-rates|arduplane``, as the companion and ``fly`` take it."""
    parser.add_argument(
        "--setpoints",
        choices=[d.value for d in SetpointDialect],
        default=SetpointDialect.BODY_RATES.value,
        help=(
            "how GUIDED is commanded: body-rates (SET_POSITION_TARGET_LOCAL_NED in BODY_FRD: forward acceleration and "
            "yaw rate; the default) or arduplane (ArduPlane's GUIDED_CHANGE_HEADING and GUIDED_CHANGE_SPEED, which a "
            "stock ArduPlane flies)"
        ),
    )
