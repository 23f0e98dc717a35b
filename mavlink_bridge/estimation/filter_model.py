"""Which motion model the companion's state filter runs (:mod:`mavlink_bridge.estimation.state_filter`): a name, without
filterpy, so that the companion's configuration and ``--help`` do not load filterpy and scipy."""

from __future__ import annotations

import enum


class FilterModel(enum.Enum):
    """Motion model of :class:`VehicleStateFilter`."""

    CONSTANT_TURN = "constant_turn"
    """Eq. 5 with constant speed and turn rate, unscented filter; estimates the turn rate."""
    CONSTANT_TURN_EKF = "constant_turn_ekf"
    """The same model, extended filter (analytic Jacobians): the same figures at a fraction of the cost."""
    CONSTANT_VELOCITY = "constant_velocity"
    """Straight-line motion, linear filter; cheaper, no turn rate, lags in turns."""
