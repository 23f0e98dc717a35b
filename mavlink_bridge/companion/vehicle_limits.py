"""What the vehicle says it achieves (:mod:`tssac_core.wire.vehicle_limits`), read before a monitored flight, and what
the monitor makes of it.

The monitor's backups are maximum-rate turns, and eq. 5's are also braking turns at the scenario's acceleration
limit. A vehicle that publishes its achievable limits (the SITL vehicles do, ``ACHV_*``) is held to them:

* one that turns slower than the scenario's limit cannot fly the backups: the companion refuses to fly it, in one
  line, before it arms;
* one that brakes at less than the scenario's acceleration limit (a JSBSim F-16: 0.9 m/s/s at its worst) cannot
  fly eq. 5's braking backups: the monitor does not offer them (the constant-speed ones remain; the airframe
  response's prediction never offers them).

A stock ArduPlane publishes none of the ``ACHV_*`` parameters; its turn is then bounded by its own ``ROLL_LIMIT_DEG``
at its ``AIRSPEED_MAX`` (and its braking, unknown, is taken at the scenario's). A vehicle that publishes neither is
taken at the scenario's limits, and the status says so (``vehicle_limits: null``).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

from mavlink_bridge.link.connection import MavLink
from tssac_core.wire.vehicle_limits import Achievable, ArduPlaneParam, LimitParam

_log = logging.getLogger(__name__)

_SLACK = 1e-6
"""Relative slack of the comparisons: a parameter travels as a float32."""


def read_achievable(link: MavLink, timeout_s: float, attempts: int) -> Achievable | None:
    """What the vehicle says it achieves: its ``ACHV_*`` parameters, else its ArduPlane bank limit and top airspeed;
    None if it publishes neither (or values that bound nothing: logged)."""
    values = link.read_params([p.value for p in (*LimitParam, *ArduPlaneParam)], timeout_s, attempts)
    try:
        return Achievable.of(values)
    except ValueError as exc:
        _log.warning("the vehicle's limits are ignored: %s", exc)
        return None


@dataclass(frozen=True)
class MonitorFit:
    """What the monitor keeps of its backups on a vehicle."""

    refusal: str | None
    """Why the vehicle cannot fly the monitor's backups (one line), or None."""
    braking_backups: bool
    """eq. 5's braking backups may be offered."""


def monitor_fit(achievable: Achievable | None, turn_rate_max_rad_s: float, accel_max_m_s2: float) -> MonitorFit:
    """What the monitor keeps (module docstring) on a vehicle that achieves ``achievable`` (None: it does not say)
    when the scenario's limits are ``turn_rate_max_rad_s`` and ``accel_max_m_s2``."""
    if achievable is None:
        return MonitorFit(None, True)
    if achievable.turn_rate_max_rad_s < turn_rate_max_rad_s * (1.0 - _SLACK):
        return MonitorFit(
            f"the vehicle turns at most {achievable.turn_rate_max_deg_s:.3g} deg/s ({achievable.source}): the "
            f"monitor's backups turn at the scenario's {math.degrees(turn_rate_max_rad_s):g} deg/s",
            False,
        )
    decel = achievable.decel_max_m_s2
    return MonitorFit(None, decel is None or decel >= accel_max_m_s2 * (1.0 - _SLACK))


def describe(achievable: Achievable | None) -> str:
    """What the vehicle said, after "the vehicle": one log line's worth."""
    if achievable is None:
        return "publishes no achievable limits (the scenario's stand)"
    turn = f"achieves {achievable.turn_rate_max_deg_s:.3g} deg/s"
    accel, decel = achievable.accel_max_m_s2, achievable.decel_max_m_s2
    if accel is None or decel is None:
        return f"{turn} ({achievable.source}), its acceleration unpublished"
    return f"{turn}, +{accel:.3g} / -{decel:.3g} m/s/s"
