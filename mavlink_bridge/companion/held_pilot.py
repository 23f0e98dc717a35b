"""Who flies the UAV: a :class:`tssac_core.sim.pilots.Pilot` (the type the batched world's Team flies too) held on
the vehicle's clock. `make_pilot` picks one from a `CompanionConfig`: a trained role policy
(:class:`~tssac_core.sim.pilots.PolicyPilot`), the guidance controller, `straight` (holds heading and speed: a test
pilot that flies into whatever lies ahead), or an adversary (:mod:`tssac_core.sim.adversaries`: a test pilot
built to break the runtime-assurance monitor, the very function the batched world flies).

Every pilot says how many ticks its actions hold (``repeat``) and whether its last action was a new
decision (``decided``): the runtime-assurance monitor decides at the pilot's decisions."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from mavlink_bridge.companion.config import STRAIGHT, CompanionConfig
from tssac_core.deploy.numpy_actor import load_actor
from tssac_core.sim.adversaries import ADVERSARY_NAMES, Adversary, AdversaryPilot
from tssac_core.sim.pilot_view import PilotView
from tssac_core.sim.pilots import GuidancePilot, Pilot, PolicyPilot, StraightPilot
from tssac_core.sim.routes import RouteConfig, RouteMap
from tssac_core.sim.scenario import Role
from tssac_core.sim.world_state import WorldState


class DecisionClock:
    """Decision ticks 0, k, 2k, ... of the vehicle's clock (k = ``every``); a tick skipped by a slow companion
    moves the decision to the next tick seen. The pilots hold their actions on it, and the runtime-assurance
    monitor decides on it (Team holds actions the same way in the batched world)."""

    def __init__(self, every: int) -> None:
        self.every = max(1, every)
        self._next = 0

    def reset(self) -> None:
        self._next = 0

    @property
    def next_step(self) -> int:
        """The next decision tick on the grid (after the ticks seen so far)."""
        return self._next

    def due(self, step: int, force: bool = False) -> bool:
        """Whether ``step`` is a decision tick (``force``: it is, whatever the grid says); moves the grid on."""
        if force or step >= self._next:
            self._next = (step // self.every + 1) * self.every
            return True
        return False


class HeldPilot:
    """A :class:`~tssac_core.sim.pilots.Pilot` flying the companion's vehicle (a state of one world): a pilot that
    decides every tick (the guidance controller) is asked every tick; one with an ``action_repeat`` k decides at
    ticks 0, k, 2k, ... of the vehicle's clock (:class:`DecisionClock`) and its action is held in between, as the
    batched world's Team holds it. The ``nan`` adversary's action is NaN: the companion's failsafe decides what
    flies."""

    def __init__(self, pilot: Pilot) -> None:
        self.pilot = pilot
        self.name = pilot.name
        self.repeat = max(1, int(pilot.action_repeat))
        self.decided = False
        self._held: np.ndarray | None = None
        self._clock = DecisionClock(self.repeat)

    def reset(self) -> None:
        self._held = None
        self._clock.reset()

    def action(self, state: Callable[[], WorldState], role_index: int, step: int) -> np.ndarray:
        """The action (2,) for vehicle tick ``step``; ``state()``: the vehicle's estimate, the layout and the flags,
        built only at a decision (between them the held action flies, whatever the state)."""
        self.decided = self.repeat == 1 or self._clock.due(step, force=self._held is None)
        if self.decided:
            self._held = np.asarray(self.pilot.actions(state(), role_index)[0], dtype=np.float64).reshape(2)
        assert self._held is not None
        return self._held

    def next_decision_step(self, step: int) -> int:
        """The first tick after ``step`` (asked already) at which the action may change: the next one for a pilot that
        decides every tick or holds nothing, else its next decision tick."""
        if self.repeat == 1 or self._held is None:
            return step + 1
        return max(step + 1, self._clock.next_step)


def policy_pilot(path: Path, role: Role, route: RouteConfig = RouteConfig()) -> PolicyPilot:
    """The trained policy in ``path`` (<role>.npz: numpy only; <role>.onnx: onnxruntime; <role>.pt: imports torch),
    named by its path, observing the route field ``route``."""
    return PolicyPilot(load_actor(path, role), routes=RouteMap(route), name=str(path))


def make_pilot(config: CompanionConfig) -> HeldPilot:
    """The pilot a configuration names: its model, else ``--pilot`` (guidance by default)."""
    pilot: Pilot
    if config.model is not None:
        pilot = policy_pilot(config.model, config.role, PilotView.asked_by(config.shield).route())
    elif config.pilot == STRAIGHT:
        pilot = StraightPilot()
    elif config.pilot in ADVERSARY_NAMES:
        pilot = AdversaryPilot(Adversary(config.pilot))
    else:
        pilot = GuidancePilot()
    return HeldPilot(pilot)
