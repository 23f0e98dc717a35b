"""Which epoch a role ships: after every epoch, fly the greedy policy on held-out layouts and keep the best.

Off-policy Lagrangian training does not improve monotonically: the multiplier and the policy chase each
other, and a role that flew well for ten epochs can be in a bad phase at the last one (our first strike
role was: 100% task success in epochs 29-34 of training, 34% mission success from its last epoch). So
the training loops validate each epoch's checkpoint and ship the best one, as an evaluation callback
would: missions with the role's deterministic policy, its trained predecessors, and the guidance
controller flying the roles not trained yet (so that the decoy and detect are judged by whether the
mission they enable succeeds, not only by whether they touch their zone once).

The validation layouts are drawn from the training seed and the role, once, and kept for the whole run,
so the epochs are compared on the same missions; they are never the evaluation layouts of the
published figures (those use their own seeds on the command line).

Best, for the learners that are given the cost limit C (TSSAC, SAC-Lagrangian, PPO-Lagrangian, CPO) =
the highest mission success among epochs whose mean hazard cost of the role is within the scenario's
limit; if no epoch is within it yet, the lowest cost. For those that are not (SAC, SAC with a penalty,
PPO) = the highest mission success, whatever the cost: selecting them within C would make the selection
their safety mechanism (plain SAC's decoy flew 96% of the validation missions at a cost of 60-420 per
mission and shipped the one epoch within C, at 44%), and the comparison is between learners, not
between selections. Ties go to the lower cost, then to the earlier epoch.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from tssac_core.sim.missions import fly_missions
from tssac_core.sim.observation import ObservationMode
from tssac_core.deploy.policy import Policy
from tssac_core.sim.scenario import ROLES, Role, Scenario, sample_layout
from tssac_core.sim.team import GUIDANCE, Pilot

SEED_TAG = 0x5A11D
"""Mixed into the validation layouts' seed, so they differ from the training layouts of the same seed."""


@dataclass(frozen=True)
class Score:
    epoch: int
    mission_success: float
    task_success: float
    mean_cost: float
    """The role's mean hazard cost per mission."""
    cost_limit: float

    def key(self, within_limit: bool = True) -> tuple[bool, float, float, int]:
        """The larger the better (module docstring); ``within_limit``: the cost limit comes first."""
        within = self.mean_cost <= self.cost_limit or not within_limit
        return (within, self.mission_success if within else 0.0, -self.mean_cost, -self.epoch)


class EpochSelector:
    """Validates each epoch's checkpoint of one role and keeps the best as ``resume/<role>-best.pt``."""

    def __init__(self, scenario: Scenario, role: Role, out: Path, episodes: int, seed: int,
                 teammates: Mapping[str, Pilot], mode: ObservationMode, within_limit: bool = True) -> None:
        self.scenario, self.role, self.episodes, self.mode = scenario, role, episodes, mode
        self.within_limit = within_limit
        rng = np.random.default_rng([seed, role.index, SEED_TAG])
        self.layouts = [sample_layout(scenario, rng) for _ in range(episodes)]
        self.pilots: list[Pilot] = [teammates.get(r.value) if r.index < role.index else GUIDANCE for r in ROLES]
        self.candidate = out / "resume" / f"{role.value}-last.pt"
        self.best_path = out / "resume" / f"{role.value}-best.pt"
        self.best: Score | None = None

    def after_epoch(self, epoch: int, write_checkpoint: Callable[[Path], None]) -> dict[str, float]:
        """Write this epoch's checkpoint, validate it, keep it if best; returns the metrics columns."""
        if self.episodes <= 0:
            return {}
        self.candidate.parent.mkdir(parents=True, exist_ok=True)
        write_checkpoint(self.candidate)
        pilots = list(self.pilots)
        pilots[self.role.index] = Policy.load(self.candidate, self.role)
        results = fly_missions(self.scenario, pilots, len(self.layouts), 0, self.mode, layouts=self.layouts)
        j = self.role.index
        score = Score(epoch, float(results.success.mean()), float(results.task_done[:, j].mean()),
                      float(results.cost[:, j].mean()), self.scenario.cost_limit)
        if self.best is None or score.key(self.within_limit) > self.best.key(self.within_limit):
            _copy_atomic(self.candidate, self.best_path)
            self.best = score
        return {"val_mission_success": score.mission_success, "val_task_success": score.task_success,
                "val_cost": score.mean_cost, "best_epoch": self.best.epoch}

    def finish(self, final: Path, write_checkpoint: Callable[[Path], None]) -> Score | None:
        """Ship the best epoch's checkpoint as ``final`` (without validation: the last epoch's)."""
        if self.best is None:
            write_checkpoint(final)
        else:
            _copy_atomic(self.best_path, final)
        return self.best

    def state_dict(self) -> dict[str, Any]:
        return {"best": asdict(self.best) if self.best else None}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.best = Score(**state["best"]) if state.get("best") else None


def _copy_atomic(src: Path, dst: Path) -> None:
    tmp = dst.with_name(dst.name + ".tmp")
    shutil.copyfile(src, tmp)
    os.replace(tmp, dst)
