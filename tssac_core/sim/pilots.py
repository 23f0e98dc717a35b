"""Who flies a UAV: one :class:`Pilot` type, for the batched world's :class:`~tssac_core.sim.team.Team` and for a
companion computer (:mod:`mavlink_bridge.companion.held_pilot`) alike.

A pilot flies one role in every world of a :class:`~tssac_core.sim.world_state.WorldState` (the batched world's
N worlds, or a companion's one) and makes a new decision every ``action_repeat`` steps; whoever flies it holds
its actions in between (the Team on each world's step count, a companion on its vehicle's clock). The kinds:

- :class:`GuidancePilot`: the rule-based guidance controller (:mod:`tssac_core.sim.guidance`), every step;
- :class:`PolicyPilot`: a trained policy, or any callable ``obs (N, d) -> action (N, 2)``, on the observations of
  its role (in the policy's ``observation_mode``), every ``action_repeat`` steps it was trained with;
- :class:`~tssac_core.sim.adversaries.AdversaryPilot`: a test pilot built to break the runtime-assurance monitor;
- :class:`StraightPilot`: heading and speed held (a test pilot that flies into whatever lies ahead).

:data:`PilotSpec` is what callers may name a pilot by (``"guidance"``, a callable, a Pilot, or None for a parked
UAV); :func:`as_pilot` makes the Pilot.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, runtime_checkable

import numpy as np

from tssac_core.sim.guidance import Guidance
from tssac_core.sim.observation import ObservationMode, observe
from tssac_core.sim.routes import RouteMap
from tssac_core.sim.world_state import WorldState

GUIDANCE = "guidance"
STRAIGHT = "straight"
LEARNER = "learner"
"""The slot of the role being trained (:func:`tssac_core.sim.role_task.resolve_pilots`): the learner sets its action."""


@runtime_checkable
class Pilot(Protocol):
    """Flies one role in every world of a state; a new decision every ``action_repeat`` steps."""

    @property
    def name(self) -> str: ...

    @property
    def action_repeat(self) -> int: ...

    def actions(self, state: WorldState, role_index: int) -> np.ndarray:
        """The actions (N, 2) in [-1, 1] of vehicle ``role_index`` in every world (decided now)."""
        ...


PilotSpec = str | Callable[[np.ndarray], np.ndarray] | Pilot | None
"""A pilot as callers name it: ``"guidance"``, a callable policy, a :class:`Pilot`, :data:`LEARNER`, or None (the UAV
is parked: it does not move and no task or cost of it counts)."""


class GuidancePilot:
    """The guidance controller. It computes every vehicle's action at once: one instance flying several roles of
    the same state computes them once (it remembers the last state it was asked about)."""

    name = GUIDANCE
    action_repeat = 1

    def __init__(self) -> None:
        self.guidance = Guidance()
        self._state: WorldState | None = None
        self._actions = np.zeros((0, 3, 2))

    def actions(self, state: WorldState, role_index: int) -> np.ndarray:
        if state is not self._state:
            self._actions = self.guidance.actions(state)
            self._state = state
        return self._actions[:, role_index]


class PolicyPilot:
    """A callable ``obs (N, d) -> action (N, 2)`` on its role's observations: in its ``observation_mode`` if it has
    one (trained policies do), else ``default_mode``; its decisions every ``action_repeat`` steps if it has one."""

    def __init__(
        self,
        policy: Callable[[np.ndarray], np.ndarray],
        default_mode: ObservationMode = ObservationMode.ROUTE,
        routes: RouteMap | None = None,
        name: str | None = None,
    ) -> None:
        self.policy = policy
        self.mode: ObservationMode = getattr(policy, "observation_mode", default_mode)
        self.action_repeat = max(1, int(getattr(policy, "action_repeat", 1)))
        self.routes = routes if routes is not None else RouteMap()
        """The route fields of the route observation (share one among the pilots of a world: a field per layout)."""
        self.name = name if name is not None else type(policy).__name__

    def actions(self, state: WorldState, role_index: int) -> np.ndarray:
        return np.asarray(self.policy(observe(state, role_index, self.mode, self.routes)), dtype=np.float64)


class StraightPilot:
    """Holds heading and speed ([omega, u] = [0, 0]) for ever, one decision per second (10 steps): a pilot that flies
    into a radar or out of the area when one lies ahead, to show what the monitor does."""

    name = STRAIGHT
    action_repeat = 10

    def actions(self, state: WorldState, role_index: int) -> np.ndarray:
        return np.zeros((state.n, 2))


def check_pilot(pilot: PilotSpec, role_name: str) -> None:
    if pilot is None or callable(pilot) or isinstance(pilot, Pilot) or pilot == GUIDANCE:
        return
    raise ValueError(
        f"pilot for {role_name} must be 'guidance', None or a callable obs -> action (or a Pilot), got {pilot!r}"
    )


def as_pilot(spec: PilotSpec, default_mode: ObservationMode, routes: RouteMap, guidance: GuidancePilot) -> Pilot | None:
    """The Pilot ``spec`` names: ``guidance`` for ``"guidance"``, a callable as a :class:`PolicyPilot` observing with
    ``routes``; a Pilot as it is; None for None and for :data:`LEARNER` (whose action is not the team's)."""
    if spec is None or spec == LEARNER:
        return None
    if isinstance(spec, Pilot):
        return spec
    if callable(spec):
        return PolicyPilot(spec, default_mode, routes)
    if spec == GUIDANCE:
        return guidance
    raise ValueError(f"unknown pilot {spec!r}")


def decision_interval(pilot: PilotSpec) -> int:
    """World steps between a pilot's decisions: its ``action_repeat`` (1 for the guidance controller)."""
    if callable(pilot) or isinstance(pilot, Pilot):
        return max(1, int(getattr(pilot, "action_repeat", 1)))
    return 1
