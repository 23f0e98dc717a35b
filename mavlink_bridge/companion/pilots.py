"""Who flies the UAV: a trained role policy (`PolicyPilot`), the guidance controller (`GuidancePilot`), or
`StraightPilot` (holds heading and speed: a test pilot that flies into whatever lies ahead).

Every pilot says how many ticks its actions hold (``repeat``) and whether its last action was a new
decision (``decided``): the runtime-assurance monitor decides at the pilot's decisions."""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import numpy as np

from mavlink_bridge.companion.config import GUIDANCE, STRAIGHT
from tssac_core.deploy.numpy_actor import load_actor
from tssac_core.sim.guidance import Guidance
from tssac_core.sim.observation import ObservationMode, observe
from tssac_core.sim.routes import RouteMap
from tssac_core.sim.scenario import Role
from tssac_core.sim.world import World


class Pilot(Protocol):
    name: str
    repeat: int
    decided: bool

    def reset(self) -> None: ...
    def action(self, world: World, role_index: int, step: int) -> np.ndarray: ...


class GuidancePilot:
    """The rule-based guidance controller (:mod:`tssac_core.sim.guidance`) for one role."""

    name = GUIDANCE
    repeat = 1
    decided = True

    def __init__(self) -> None:
        self._guidance = Guidance()

    def reset(self) -> None:
        pass

    def action(self, world: World, role_index: int, step: int) -> np.ndarray:
        return np.asarray(self._guidance.actions(world)[0, role_index], dtype=np.float64)


class StraightPilot:
    """Holds heading and speed ([omega, u] = [0, 0]) for ever, one decision per second (10 ticks): a pilot that
    flies into a radar or out of the area when one lies ahead, to show what the monitor does."""

    name = STRAIGHT
    repeat = 10

    def __init__(self) -> None:
        self.decided = True
        self._next_decision = 0

    def reset(self) -> None:
        self._next_decision = 0

    def action(self, world: World, role_index: int, step: int) -> np.ndarray:
        self.decided = step >= self._next_decision
        if self.decided:
            self._next_decision = (step // self.repeat + 1) * self.repeat
        return np.zeros(2)


class PolicyPilot:
    """A trained role policy; each action is held for ``action_repeat`` ticks, as in training."""

    def __init__(self, path: Path, role: Role) -> None:
        self.policy = load_actor(path, role)  # <role>.npz: numpy only; <role>.pt: imports torch
        self.name = str(path)
        self.repeat = max(1, int(self.policy.action_repeat))
        self.mode: ObservationMode = self.policy.observation_mode
        self.routes = RouteMap()
        self._held: np.ndarray | None = None
        self._next_decision = 0
        self.decided = False

    def reset(self) -> None:
        self._held = None
        self._next_decision = 0

    def action(self, world: World, role_index: int, step: int) -> np.ndarray:
        # Decisions at ticks 0, k, 2k, ... of the vehicle's clock (Team holds actions the same way);
        # a tick skipped by a slow companion moves the decision to the next tick seen.
        self.decided = self._held is None or step >= self._next_decision
        if self.decided:
            obs = observe(world, role_index, self.mode, self.routes)[0]
            self._held = np.asarray(self.policy.act(obs), dtype=np.float64).reshape(2)
            self._next_decision = (step // self.repeat + 1) * self.repeat
        assert self._held is not None
        return self._held
