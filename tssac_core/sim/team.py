"""Who flies each UAV: the guidance controller, a policy, or nobody (parked).

A *pilot* is one of:
- ``"guidance"``: the rule-based controller (:mod:`tssac_core.sim.guidance`);
- a callable ``obs (N, d) -> action (N, 2)`` on the observations of its role; if it has an attribute
  ``observation_mode`` (an :class:`ObservationMode`, as trained policies do), it gets observations in
  that mode, else in the mode of whoever asks; if it has ``action_repeat`` = k > 1, each of its
  actions is held for k world steps (the decision interval it was trained with);
- an :class:`~tssac_core.sim.adversaries.AdversaryPilot`: a test pilot built to break the runtime-assurance
  monitor, which reads the world's state itself and decides every ``action_repeat`` steps;
- ``None``: the UAV is parked (inactive): it does not move and no task or cost of it counts.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from tssac_core.sim.adversaries import AdversaryPilot
from tssac_core.sim.guidance import Guidance
from tssac_core.sim.observation import ObservationMode, observe
from tssac_core.sim.routes import RouteMap
from tssac_core.sim.scenario import ROLES
from tssac_core.sim.world import World
from tssac_core.sim.world_state import snapshot

GUIDANCE = "guidance"
Pilot = str | Callable[[np.ndarray], np.ndarray] | AdversaryPilot | None


def check_pilot(pilot: Pilot, role_name: str) -> None:
    if pilot is None or callable(pilot) or isinstance(pilot, AdversaryPilot) or pilot == GUIDANCE:
        return
    raise ValueError(
        f"pilot for {role_name} must be 'guidance', None or a callable obs -> action (or an AdversaryPilot), "
        f"got {pilot!r}"
    )


def decision_interval(pilot: Pilot) -> int:
    """World steps between a pilot's decisions: its ``action_repeat`` (1 for the guidance controller)."""
    if callable(pilot) or isinstance(pilot, AdversaryPilot):
        return max(1, int(getattr(pilot, "action_repeat", 1)))
    return 1


class Team:
    """The pilots of the three vehicles of a World; holds actions of pilots with an action_repeat."""

    def __init__(self, pilots: Sequence[Pilot], default_mode: ObservationMode) -> None:
        self.pilots = list(pilots)
        self._flown = [(j, pilot) for j, pilot in enumerate(self.pilots) if pilot is not None]
        """The vehicles someone flies (a parked one's action stays zero)."""
        self.default_mode = default_mode
        self.guidance = Guidance()
        self.routes = RouteMap()
        """Route fields for pilots that observe in route mode."""
        self._held: np.ndarray | None = None

    def actions(self, world: World, skip: int | None = None) -> np.ndarray:
        """Actions (N, 3, 2) of every flown vehicle; vehicle ``skip`` (the learner) is left at zero."""
        if self._held is None or self._held.shape[0] != world.n:
            self._held = np.zeros((world.n, len(ROLES), 2))
        actions = np.zeros((world.n, len(ROLES), 2))
        state = snapshot(world)
        guided = None
        for j, pilot in self._flown:
            if j == skip:
                continue
            if pilot == GUIDANCE:
                if guided is None:
                    guided = self.guidance.actions(state)
                actions[:, j] = guided[:, j]
            elif isinstance(pilot, AdversaryPilot):
                due = world.steps % pilot.action_repeat == 0
                if due.any():
                    self._held[:, j] = np.where(due[:, None], pilot.actions(state, j), self._held[:, j])
                actions[:, j] = self._held[:, j]
            elif callable(pilot):
                mode = getattr(pilot, "observation_mode", self.default_mode)
                repeat = decision_interval(pilot)
                due = world.steps % repeat == 0
                if due.any():  # between decisions nobody needs the pilot: skip its forward pass
                    fresh = np.asarray(pilot(observe(state, j, mode, self.routes)), dtype=np.float64)
                    self._held[:, j] = np.where(due[:, None], fresh, self._held[:, j])
                actions[:, j] = self._held[:, j]
        return actions
