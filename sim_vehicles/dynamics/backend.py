"""The seam between the SITL's vehicles and their physics (DESIGN.md section 7), as ArduPilot's SITL keeps its
physics backends behind one aircraft interface: each backend moves world 0's three vehicles through one step (the
world's :meth:`~tssac_core.sim.world.World.integrate`, or :meth:`~tssac_core.sim.world.World.set_states` from another
model) and says what each vehicle's true state is; the world then judges the mission on those states
(:meth:`~tssac_core.sim.world.World.mission_step`). The MAVLink side sees only the truths.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import numpy as np

from sim_vehicles.autopilot.telemetry import VehicleTruth
from sim_vehicles.dynamics.kinematic import KinematicDynamics
from tssac_core.sim.airframe_response import ResponseFileError, load_response
from tssac_core.sim.scenario import Dynamics, DynamicsModel
from tssac_core.sim.world import World
from tssac_core.wire.vehicle_limits import Achievable


class DynamicsError(Exception):
    """A backend that cannot fly this scenario (an unknown airframe, a model directory that does not load);
    ``str()`` is one line."""


class VehicleDynamics(Protocol):
    """What the world runner asks of a physics backend."""

    name: str
    """What flies, for logs and reports ("kinematic", "jsbsim f16")."""
    achievable: list[Achievable]
    """What each vehicle achieves anywhere in its speed envelope (its ACHV_* parameters,
    :mod:`tssac_core.wire.vehicle_limits`)."""
    bank_limits_deg: list[float]
    """Each vehicle's largest bank (its ROLL_LIMIT_DEG, ArduPlane's name)."""

    def truths(self) -> list[VehicleTruth]:
        """The vehicles' true states now (after the last step, or at the start)."""
        ...

    def advance(self, actions: np.ndarray) -> list[VehicleTruth]:
        """Move the running vehicles through one world step under ``actions`` (1, 3, 2), [omega, u] in [-1, 1];
        return their truths."""
        ...

    def close(self) -> None:
        """Release what the backend holds (idempotent)."""
        ...


def make_dynamics(dynamics: Dynamics, world: World, seed: int, monitor_response: Path | None = None) -> VehicleDynamics:
    """The backend ``dynamics`` names, for ``world`` (reset to its layout); raises :class:`DynamicsError`, also for a
    ``monitor_response`` (the airframe response the companions' monitors predict with) fitted to another airframe, or
    to another version of this one."""
    if dynamics.model is DynamicsModel.KINEMATIC:
        return KinematicDynamics(world)
    # JSBSim is imported only when it flies: the kinematic world and its fork server never load it.
    from sim_vehicles.dynamics.jsbsim_airframe import AirframeError, airframe_path, load_airframe
    from sim_vehicles.dynamics.jsbsim_dynamics import JsbsimDynamics

    try:
        if monitor_response is not None:
            load_response(monitor_response, airframe_path(dynamics.aircraft))
        return JsbsimDynamics(world, load_airframe(dynamics.aircraft), seed)
    except (AirframeError, ResponseFileError) as exc:
        raise DynamicsError(str(exc)) from None
