"""The vehicle's parameters (MAVLink parameter protocol).

=================  ======  =========  ==========================================================
name               type    access     meaning
=================  ======  =========  ==========================================================
``SYSID_THISMAV``  INT32   read-only  this vehicle's MAVLink system id (1 decoy, 2 detect, 3 strike)
``GUID_TIMEOUT``   REAL32  settable   setpoint-timeout failsafe, seconds (0.1 .. 60); ArduCopter's name
``SIM_DT``         REAL32  read-only  world step, seconds
``SIM_TURN_MAX``   REAL32  read-only  turn-rate limit (|yaw_rate| is clipped to it), deg/s
``SIM_ACCEL_MAX``  REAL32  read-only  acceleration limit (|afx| is clipped to it), m/s/s
``SIM_SPD_MIN``    REAL32  read-only  minimum speed, m/s
``SIM_SPD_MAX``    REAL32  read-only  maximum speed, m/s
``ACHV_TURN_MAX``  REAL32  read-only  the turn rate the vehicle achieves anywhere in its envelope, deg/s
``ACHV_ACCEL_MAX`` REAL32  read-only  the forward acceleration it achieves anywhere in it, m/s/s
``ACHV_DECEL_MAX`` REAL32  read-only  the deceleration it achieves anywhere in it, m/s/s (a magnitude)
``ROLL_LIMIT_DEG`` REAL32  read-only  the largest bank it flies, deg (ArduPlane's name; the point mass: the bank of
                                      a coordinated turn at the turn-rate limit at the top speed)
``AIRSPEED_MAX``   REAL32  read-only  the top airspeed, m/s (ArduPlane's name; the same as SIM_SPD_MAX)
``WP_LOITER_RAD``  REAL32  settable   loiter / RTL circle radius, m (1 .. 32767; ArduPlane's name and
                                      default 60: the radius flown is at least v / (0.8 turn limit))
``FS_GCS_ENABL``   INT32   settable   datalink failsafe: 0 off (ArduPlane's default), 1 on
``FS_LONG_TIMEOUT`` REAL32 settable   datalink failsafe after this many wall seconds without a client
                                      message (1 .. 300, default 5, as ArduPlane)
``FS_LONG_ACTN``   INT32   settable   0: RTL from MANUAL, continue in auto modes; 1: RTL from any mode
=================  ======  =========  ==========================================================

The limits are read-only because they are the world's physics (the scenario's ``vehicles:``
section, which the policies were trained on); the ``ACHV_*`` ones are what the physics backend achieves of
them (:mod:`tssac_core.wire.vehicle_limits`: the point mass all of them, an airframe what its file declares),
which a companion's monitor reads before it flies. Values travel as floats; INT32 values are the
integer cast to float (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST, as ArduPilot does). A PARAM_SET
that is refused (read-only, out of range, not finite) is answered as ArduPilot 4.6 does: a PARAM_ERROR
(PERMISSION_DENIED, VALUE_OUT_OF_RANGE: MAVSDK returns that error at once), a STATUSTEXT saying why (one
chunk, at most 50 characters) and a PARAM_VALUE holding the unchanged value; a PARAM_SET or
PARAM_REQUEST_READ of an unknown name gets PARAM_ERROR DOES_NOT_EXIST.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from tssac_core.wire.vehicle_limits import Achievable, ArduPlaneParam, coordinated_bank_deg


@dataclass(frozen=True)
class ParamRefusal:
    """Why a PARAM_SET was refused: the MAV_PARAM_ERROR code and one STATUSTEXT (at most 50 characters)."""

    error: int
    text: str


@dataclass
class Param:
    name: str
    value: float
    param_type: int
    writable: bool = False
    low: float = -math.inf
    high: float = math.inf


class ParamTable:
    """An ordered set of parameters (index = position)."""

    def __init__(self, params: list[Param]) -> None:
        self._params = params
        self._by_name = {p.name: i for i, p in enumerate(params)}

    def __len__(self) -> int:
        return len(self._params)

    def __iter__(self) -> Iterator[Param]:
        return iter(self._params)

    def index(self, name: str) -> int | None:
        return self._by_name.get(name)

    def at(self, index: int) -> Param | None:
        return self._params[index] if 0 <= index < len(self._params) else None

    def get(self, name: str) -> Param | None:
        i = self._by_name.get(name)
        return None if i is None else self._params[i]

    def set(self, name: str, value: float) -> ParamRefusal | None:
        """Set a parameter; returns None on success, else why it was refused.

        The text fits one STATUSTEXT whatever the value: a name has at most 16 characters, a value at most 11
        (5 significant digits), a range at most 10 ("0.1..32767")."""
        p = self.get(name)
        if p is None:
            return ParamRefusal(mavlink2.MAV_PARAM_ERROR_DOES_NOT_EXIST, f"{name[:16]}: no such parameter")
        if not p.writable:
            return ParamRefusal(mavlink2.MAV_PARAM_ERROR_PERMISSION_DENIED, f"{name} is read-only")
        if not math.isfinite(value) or not (p.low <= value <= p.high):
            return ParamRefusal(
                mavlink2.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE, f"{name}: {value:.5g} not in {p.low:g}..{p.high:g}"
            )
        p.value = float(round(value)) if p.param_type == mavlink2.MAV_PARAM_TYPE_INT32 else float(value)
        return None


def vehicle_params(
    sysid: int,
    setpoint_timeout_s: float,
    dt_s: float,
    turn_max_deg_s: float,
    accel_max_m_s2: float,
    speed_min_m_s: float,
    speed_max_m_s: float,
    achievable: Achievable | None = None,
    bank_limit_deg: float | None = None,
) -> ParamTable:
    """The table of the module docstring; ``achievable`` None: the limits themselves, ``bank_limit_deg`` None: a
    coordinated turn's at them (the point mass)."""
    real, int32 = mavlink2.MAV_PARAM_TYPE_REAL32, mavlink2.MAV_PARAM_TYPE_INT32
    achieved = achievable or Achievable.point_mass(turn_max_deg_s, accel_max_m_s2)
    if bank_limit_deg is None:
        bank_limit_deg = coordinated_bank_deg(turn_max_deg_s, speed_max_m_s)
    return ParamTable(
        [
            Param("SYSID_THISMAV", float(sysid), int32),
            Param("GUID_TIMEOUT", setpoint_timeout_s, real, writable=True, low=0.1, high=60.0),
            Param("SIM_DT", dt_s, real),
            Param("SIM_TURN_MAX", turn_max_deg_s, real),
            Param("SIM_ACCEL_MAX", accel_max_m_s2, real),
            Param("SIM_SPD_MIN", speed_min_m_s, real),
            Param("SIM_SPD_MAX", speed_max_m_s, real),
            *(Param(name.value, value, real) for name, value in achieved.values().items()),
            Param(ArduPlaneParam.ROLL_LIMIT.value, bank_limit_deg, real),
            Param(ArduPlaneParam.AIRSPEED_MAX.value, speed_max_m_s, real),
            Param("WP_LOITER_RAD", 60.0, real, writable=True, low=1.0, high=32767.0),
            Param("FS_GCS_ENABL", 0.0, int32, writable=True, low=0.0, high=1.0),
            Param("FS_LONG_TIMEOUT", 5.0, real, writable=True, low=1.0, high=300.0),
            Param("FS_LONG_ACTN", 0.0, int32, writable=True, low=0.0, high=1.0),
        ]
    )
