"""Who flies the UAV: a trained role policy (`PolicyPilot`), the guidance controller (`GuidancePilot`),
`StraightPilot` (holds heading and speed: a test pilot that flies into whatever lies ahead), or an
`AdversarialPilot` (:mod:`tssac_core.sim.adversaries`: a test pilot built to break the runtime-assurance
monitor, the very function the batched world flies). `make_pilot` picks one from a `CompanionConfig`.

Every pilot says how many ticks its actions hold (``repeat``) and whether its last action was a new
decision (``decided``): the runtime-assurance monitor decides at the pilot's decisions."""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import numpy as np

from mavlink_bridge.companion.config import GUIDANCE, STRAIGHT, CompanionConfig
from tssac_core.deploy.numpy_actor import load_actor
from tssac_core.sim.adversaries import ADVERSARY_NAMES, DECISION_STEPS, Adversary, adversary_actions, situation
from tssac_core.sim.guidance import Guidance
from tssac_core.sim.observation import ObservationMode, observe
from tssac_core.sim.routes import RouteMap
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

    def due(self, step: int, force: bool = False) -> bool:
        """Whether ``step`` is a decision tick (``force``: it is, whatever the grid says); moves the grid on."""
        if force or step >= self._next:
            self._next = (step // self.every + 1) * self.every
            return True
        return False


class Pilot(Protocol):
    name: str
    repeat: int
    decided: bool

    def reset(self) -> None: ...
    def action(self, state: WorldState, role_index: int, step: int) -> np.ndarray: ...


class GuidancePilot:
    """The rule-based guidance controller (:mod:`tssac_core.sim.guidance`) for one role."""

    name = GUIDANCE
    repeat = 1
    decided = True

    def __init__(self) -> None:
        self._guidance = Guidance()

    def reset(self) -> None:
        pass

    def action(self, state: WorldState, role_index: int, step: int) -> np.ndarray:
        return np.asarray(self._guidance.actions(state)[0, role_index], dtype=np.float64)


class StraightPilot:
    """Holds heading and speed ([omega, u] = [0, 0]) for ever, one decision per second (10 ticks): a pilot that
    flies into a radar or out of the area when one lies ahead, to show what the monitor does."""

    name = STRAIGHT
    repeat = 10

    def __init__(self) -> None:
        self.decided = True
        self._clock = DecisionClock(self.repeat)

    def reset(self) -> None:
        self._clock.reset()

    def action(self, state: WorldState, role_index: int, step: int) -> np.ndarray:
        self.decided = self._clock.due(step)
        return np.zeros(2)


class AdversarialPilot:
    """An adversary (:func:`tssac_core.sim.adversaries.adversary_actions`) on the companion's one-world mirror of
    its vehicle; it decides at ticks 0, 10, 20, ... of the vehicle's clock, as in the batched world, and holds
    its action in between. The ``nan`` adversary's action is NaN: the companion's failsafe decides what flies."""

    repeat = DECISION_STEPS

    def __init__(self, adversary: Adversary) -> None:
        self.adversary = adversary
        self.name = adversary.value
        self.decided = True
        self._held: np.ndarray | None = None
        self._clock = DecisionClock(self.repeat)

    def reset(self) -> None:
        self._held = None
        self._clock.reset()

    def action(self, state: WorldState, role_index: int, step: int) -> np.ndarray:
        self.decided = self._clock.due(step, force=self._held is None)
        if self.decided:
            actions = adversary_actions(self.adversary, situation(state, steps=step))
            self._held = np.asarray(actions[0, role_index], dtype=np.float64)
        assert self._held is not None
        return self._held


class PolicyPilot:
    """A trained role policy; each action is held for ``action_repeat`` ticks, as in training."""

    def __init__(self, path: Path, role: Role) -> None:
        self.policy = load_actor(path, role)  # <role>.npz: numpy only; <role>.pt: imports torch
        self.name = str(path)
        self.repeat = max(1, int(self.policy.action_repeat))
        self.mode: ObservationMode = self.policy.observation_mode
        self.routes = RouteMap()
        self._held: np.ndarray | None = None
        self._clock = DecisionClock(self.repeat)
        self.decided = False

    def reset(self) -> None:
        self._held = None
        self._clock.reset()

    def action(self, state: WorldState, role_index: int, step: int) -> np.ndarray:
        self.decided = self._clock.due(step, force=self._held is None)
        if self.decided:
            obs = observe(state, role_index, self.mode, self.routes)[0]
            self._held = np.asarray(self.policy.act(obs), dtype=np.float64).reshape(2)
        assert self._held is not None
        return self._held


def make_pilot(config: CompanionConfig) -> Pilot:
    """The pilot a configuration names: its model, else ``--pilot`` (guidance by default)."""
    if config.model is not None:
        return PolicyPilot(config.model, config.role)
    if config.pilot == STRAIGHT:
        return StraightPilot()
    if config.pilot in ADVERSARY_NAMES:
        return AdversarialPilot(Adversary(config.pilot))
    return GuidancePilot()
