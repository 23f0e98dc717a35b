"""What a vehicle achieves, as it publishes it: three read-only parameters of the MAVLink parameter protocol, which the
SITL vehicle answers (``sim_vehicles/autopilot/params.py``) and a companion that monitors reads before it flies
(``mavlink_bridge/companion/vehicle_limits.py``).

==================  ==========================================================================================
name                meaning (anywhere in the vehicle's speed envelope, under its own inner loop)
==================  ==========================================================================================
``ACHV_TURN_MAX``   the largest heading rate it holds, deg/s
``ACHV_ACCEL_MAX``  the forward acceleration it reaches when asked for the most, m/s/s
``ACHV_DECEL_MAX``  the deceleration it reaches when asked for the most, m/s/s (a magnitude, > 0)
==================  ==========================================================================================

The point-mass vehicle achieves its limits exactly (eq. 6: the scenario's turn-rate and acceleration limits, both
ways); an airframe achieves what its file declares for its envelope (a JSBSim F-16: the scenario's 5 deg/s, but only
5.1 m/s/s forward and 0.9 m/s/s of braking at its worst).

A stock ArduPlane publishes none of these, but two of its own parameters bound its turn: ``ROLL_LIMIT_DEG``, the
largest bank it commands, and ``AIRSPEED_MAX`` (m/s). Its slowest maximum-rate turn is a level coordinated turn at
that bank at that airspeed, omega = g tan(bank) / V (:func:`bank_limited_turn_deg_s`); its acceleration and braking
are its TECS's and are not published. The SITL vehicles answer both names too.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass


class LimitParam(enum.StrEnum):
    """The parameters' names (at most 16 characters, as MAVLink's param_id)."""

    TURN = "ACHV_TURN_MAX"
    ACCEL = "ACHV_ACCEL_MAX"
    DECEL = "ACHV_DECEL_MAX"


class ArduPlaneParam(enum.StrEnum):
    """A stock ArduPlane's parameters that bound its turn (ArduPlane 4.5's names)."""

    ROLL_LIMIT = "ROLL_LIMIT_DEG"
    AIRSPEED_MAX = "AIRSPEED_MAX"


STANDARD_GRAVITY_M_S2 = 9.80665


def bank_limited_turn_deg_s(roll_limit_deg: float, airspeed_m_s: float) -> float:
    """The heading rate of a level coordinated turn at bank ``roll_limit_deg`` and ``airspeed_m_s``: g tan(bank) / V."""
    return math.degrees(STANDARD_GRAVITY_M_S2 * math.tan(math.radians(roll_limit_deg)) / airspeed_m_s)


def coordinated_bank_deg(turn_rate_deg_s: float, airspeed_m_s: float) -> float:
    """The bank of a level coordinated turn at ``turn_rate_deg_s`` and ``airspeed_m_s``: atan(V omega / g)."""
    return math.degrees(math.atan(airspeed_m_s * math.radians(turn_rate_deg_s) / STANDARD_GRAVITY_M_S2))


@dataclass(frozen=True)
class Achievable:
    """One vehicle's achievable limits (module docstring); every given field finite and > 0."""

    turn_rate_max_deg_s: float
    accel_max_m_s2: float | None
    """None: not published (an ArduPlane)."""
    decel_max_m_s2: float | None
    """A magnitude: the vehicle slows by up to this much per second; None: not published."""
    source: str = LimitParam.TURN.value
    """Where the turn rate comes from: ``ACHV_TURN_MAX``, or an ArduPlane's bank limit at its top airspeed."""

    def __post_init__(self) -> None:
        for name in ("turn_rate_max_deg_s", "accel_max_m_s2", "decel_max_m_s2"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")

    @staticmethod
    def point_mass(turn_rate_max_deg_s: float, accel_max_m_s2: float) -> Achievable:
        """A vehicle that achieves its limits exactly (eq. 6: the command at once, both ways)."""
        return Achievable(turn_rate_max_deg_s, accel_max_m_s2, accel_max_m_s2)

    @property
    def turn_rate_max_rad_s(self) -> float:
        return math.radians(self.turn_rate_max_deg_s)

    def values(self) -> dict[LimitParam, float]:
        """The ``ACHV_*`` parameters' values, as published (what is not known is left out)."""
        values = {
            LimitParam.TURN: self.turn_rate_max_deg_s,
            LimitParam.ACCEL: self.accel_max_m_s2,
            LimitParam.DECEL: self.decel_max_m_s2,
        }
        return {name: value for name, value in values.items() if value is not None}

    @staticmethod
    def from_dict(d: Mapping[str, object]) -> Achievable:
        """From :func:`dataclasses.asdict`'s dict (a status JSON's); ValueError if it is not one."""

        def number(name: str) -> float | None:
            value = d.get(name)
            if value is None or (isinstance(value, (int, float)) and not isinstance(value, bool)):
                return None if value is None else float(value)
            raise ValueError(f"{name}: not a number: {value!r}")

        turn = number("turn_rate_max_deg_s")
        if turn is None:
            raise ValueError("turn_rate_max_deg_s missing")
        return Achievable(
            turn, number("accel_max_m_s2"), number("decel_max_m_s2"), str(d.get("source", LimitParam.TURN.value))
        )

    @staticmethod
    def of(values: dict[str, float]) -> Achievable | None:
        """From parameters read off a vehicle (by name): the three ``ACHV_*`` ones, else an ArduPlane's
        ``ROLL_LIMIT_DEG`` and ``AIRSPEED_MAX`` (the turn alone); None if neither set is there whole. ValueError if a
        value is no limit (not finite, or not > 0; a bank not in (0, 90) degrees)."""
        if all(p.value in values for p in LimitParam):
            return Achievable(values[LimitParam.TURN], values[LimitParam.ACCEL], values[LimitParam.DECEL])
        if not all(p.value in values for p in ArduPlaneParam):
            return None
        bank, airspeed = values[ArduPlaneParam.ROLL_LIMIT], values[ArduPlaneParam.AIRSPEED_MAX]
        if not (0.0 < bank < 90.0 and math.isfinite(airspeed) and airspeed > 0.0):
            raise ValueError(f"ROLL_LIMIT_DEG {bank!r} and AIRSPEED_MAX {airspeed!r} bound no turn")
        source = f"{ArduPlaneParam.ROLL_LIMIT.value} {bank:g} at {ArduPlaneParam.AIRSPEED_MAX.value} {airspeed:g} m/s"
        return Achievable(bank_limited_turn_deg_s(bank, airspeed), None, None, source)
