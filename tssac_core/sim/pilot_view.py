"""What a pilot flying behind the runtime-assurance monitor is shown: the hazards grown by the room the monitor's
backups ask for. A team trained without the monitor plans its way round the radars as close as its cost margin lets
it, and along the area's edge where the radars push it there; the monitor, which needs room for a backup's circle
(3.4 km at 300 m/s, more with an airframe's lag and in wind), then turns it away, and a turned UAV loses the time its
mission had. Shown every radar ``radar_m`` larger (its observation's edges and its route field alike) and a band
``route_edge_m`` inside the area's edge as a hazard of its route field, the same policy keeps that room itself.

None of it enters the guarantee: the monitor checks every action against the true hazards, whatever the pilot was
shown (docs/runtime_assurance.md, "Giving the team its way back")."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.sim.routes import RouteConfig
from tssac_core.sim.world_state import WorldState


@dataclass(frozen=True)
class PilotView:
    """How much larger than they are the pilot is shown the hazards."""

    radar_m: float = 0.0
    """Every radar's radius grows by this (0: as they are)."""
    route_edge_m: float = 0.0
    """The route field treats this band inside the area's edge as a hazard (0: the route as trained)."""

    @classmethod
    def asked_by(cls, shield: ShieldConfig | None) -> PilotView:
        """What the monitor ``shield`` asks the pilot to be shown; without a monitor, the truth."""
        if shield is None:
            return cls()
        return cls(shield.radar_view_margin_m, shield.route_edge_margin_m)

    @property
    def is_truth(self) -> bool:
        return self.radar_m == 0 and self.route_edge_m == 0

    def route(self) -> RouteConfig:
        """The route field the pilot observes."""
        return RouteConfig(edge_margin_m=self.route_edge_m) if self.route_edge_m else RouteConfig()

    def of(self, state: WorldState) -> WorldState:
        """``state`` as the pilot is shown it (a layout slot no radar fills stays empty)."""
        if self.radar_m == 0:
            return state
        r = state.radar_r_m
        return state._replace(radar_r_m=np.where(r > 0, r + self.radar_m, r))
