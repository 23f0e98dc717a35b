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
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass


class LimitParam(enum.StrEnum):
    """The parameters' names (at most 16 characters, as MAVLink's param_id)."""

    TURN = "ACHV_TURN_MAX"
    ACCEL = "ACHV_ACCEL_MAX"
    DECEL = "ACHV_DECEL_MAX"


@dataclass(frozen=True)
class Achievable:
    """One vehicle's achievable limits (module docstring); every field finite and > 0."""

    turn_rate_max_deg_s: float
    accel_max_m_s2: float
    decel_max_m_s2: float
    """A magnitude: the vehicle slows by up to this much per second."""

    def __post_init__(self) -> None:
        for name in ("turn_rate_max_deg_s", "accel_max_m_s2", "decel_max_m_s2"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")

    @property
    def turn_rate_max_rad_s(self) -> float:
        return math.radians(self.turn_rate_max_deg_s)

    def values(self) -> dict[LimitParam, float]:
        """The parameters' values, as published."""
        return {
            LimitParam.TURN: self.turn_rate_max_deg_s,
            LimitParam.ACCEL: self.accel_max_m_s2,
            LimitParam.DECEL: self.decel_max_m_s2,
        }

    @staticmethod
    def of(values: dict[LimitParam, float]) -> Achievable:
        """From the three parameters' values (ValueError if one is not finite and > 0)."""
        return Achievable(values[LimitParam.TURN], values[LimitParam.ACCEL], values[LimitParam.DECEL])
