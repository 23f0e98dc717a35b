"""Who flies each UAV of a batched World: a :class:`~tssac_core.sim.pilots.Pilot` per role, or nobody (parked).

The pilots are named by :data:`~tssac_core.sim.pilots.PilotSpec` (``"guidance"``, a callable policy, a Pilot such
as an :class:`~tssac_core.sim.adversaries.AdversaryPilot`, or None); the Team makes them Pilots
(:func:`~tssac_core.sim.pilots.as_pilot`), with one guidance controller and one set of route fields for all of
them, and holds each pilot's action for its ``action_repeat`` world steps (the decision interval it was trained
with).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.pilot_view import PilotView
from tssac_core.sim.pilots import GuidancePilot, PilotSpec, as_pilot
from tssac_core.sim.routes import RouteMap
from tssac_core.sim.scenario import ROLES
from tssac_core.sim.world import World
from tssac_core.sim.world_state import snapshot


class Team:
    """The pilots of the three vehicles of a World; holds actions of pilots with an action_repeat."""

    def __init__(
        self, pilots: Sequence[PilotSpec], default_mode: ObservationMode, view: PilotView = PilotView()
    ) -> None:
        self.pilots = list(pilots)
        self.default_mode = default_mode
        self.view = view
        """What the pilots are shown: the truth, unless a monitor asks for room (:mod:`tssac_core.sim.pilot_view`)."""
        self.guidance = GuidancePilot()
        self.routes = RouteMap(view.route())
        """Route fields for pilots that observe in route mode."""
        self._flown = [
            (j, pilot)
            for j, spec in enumerate(self.pilots)
            if (pilot := as_pilot(spec, default_mode, self.routes, self.guidance)) is not None
        ]
        """The vehicles someone flies (a parked one's action stays zero)."""
        self._held: np.ndarray | None = None

    def actions(self, world: World, skip: int | None = None) -> np.ndarray:
        """Actions (N, 3, 2) of every flown vehicle; vehicle ``skip`` (the learner) is left at zero."""
        if self._held is None or self._held.shape[0] != world.n:
            self._held = np.zeros((world.n, len(ROLES), 2))
        actions = np.zeros((world.n, len(ROLES), 2))
        state = self.view.of(snapshot(world))
        for j, pilot in self._flown:
            if j == skip:
                continue
            # A finished mission's step count stands still: counting it would make a decision due at every step
            # once one mission ended on a multiple of the repeat (a forward pass per step, not per decision).
            due = (world.steps % pilot.action_repeat == 0) & world.running
            if due.any():  # between decisions nobody needs the pilot: skip its forward pass
                self._held[:, j] = np.where(due[:, None], pilot.actions(state, j), self._held[:, j])
            actions[:, j] = self._held[:, j]
        return actions
