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

Tail-aware selection (``tail=True``, TrainConfig.selection "tail"): a mean over a few dozen missions cannot see
a failure that comes once in a hundred missions, so the best of 25 such epochs is often one that has them (the
winner's curse; models/tssac/README.md). Each epoch is screened on its missions with the role's figures of
:mod:`tssac_core.common.stats`: the upper end of the 95% bootstrap interval of its mean cost, the fraction of its
UAV-missions within C, its CVaR_0.95 and worst cost. An epoch is *feasible* when that upper bound is within
C and at least TAIL_WITHIN_FRACTION of its UAV-missions are; the key is (feasible, mission success if feasible,
within-C fraction, -upper bound, epoch): a tie goes to the later epoch, the one trained longer. The best
TAIL_CANDIDATES epochs by that key are kept, and when the role ends each of them flies
TAIL_FINAL_FACTOR x as many fresh selection missions (another draw from the training seed, never an
evaluation seed); the role ships the best of them by the same key on those missions alone, so that the
figure it is chosen by is not the one it was screened by.
"""

from __future__ import annotations

import json
import logging
import shutil
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import NotRequired, TypedDict

import numpy as np

from tssac_core.common.files import replace_durably
from tssac_core.common.stats import bootstrap_mean_interval, cvar, within_fraction
from tssac_core.deploy.policy import Policy, read_checkpoint
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.pilots import GUIDANCE, PilotSpec
from tssac_core.sim.scenario import ROLES, Layout, Role, Scenario, sample_layout

logger = logging.getLogger(__name__)

SEED_TAG = 0x5A11D
"""Mixed into the validation layouts' seed, so they differ from the training layouts of the same seed."""
FINAL_TAG = 1
"""Mixed in as well for the tail selection's final missions, a draw separate from the screening missions."""
TAIL_CANDIDATES = 3
"""Tail selection: the epochs kept from the screening for the final missions."""
TAIL_FINAL_FACTOR = 5
"""Tail selection: each candidate flies this many times the screening's number of missions at the role's end."""
TAIL_WITHIN_FRACTION = 0.995
"""Tail selection: the fraction of the role's UAV-missions within C that a feasible epoch keeps (issue 23's floor:
a mean within C still allows one mission in a hundred hundreds of steps inside a radar)."""


class ScoreState(TypedDict):
    """A :class:`Score` in a resume state (the fields after ``cost_limit`` are missing from older ones)."""

    epoch: int
    mission_success: float
    task_success: float
    mean_cost: float
    cost_limit: float
    cost_high: NotRequired[float]
    within_limit_fraction: NotRequired[float]
    cvar95_cost: NotRequired[float]
    max_cost: NotRequired[float]
    missions: NotRequired[int]


class SelectorState(TypedDict):
    """What :meth:`EpochSelector.state_dict` returns (``top`` is missing from older resume states)."""

    best: ScoreState | None
    top: NotRequired[list[ScoreState]]


@dataclass(frozen=True)
class Score:
    epoch: int
    mission_success: float
    task_success: float
    mean_cost: float
    """The role's mean hazard cost per mission."""
    cost_limit: float
    cost_high: float = float("nan")
    """The upper end of the 95% bootstrap interval of the role's mean cost (NaN in states older than it)."""
    within_limit_fraction: float = float("nan")
    """The fraction of the role's UAV-missions with cost <= C."""
    cvar95_cost: float = float("nan")
    max_cost: float = float("nan")
    missions: int = 0

    def state(self) -> ScoreState:
        """As a resume state holds it: every field, in order."""
        return {
            "epoch": self.epoch,
            "mission_success": self.mission_success,
            "task_success": self.task_success,
            "mean_cost": self.mean_cost,
            "cost_limit": self.cost_limit,
            "cost_high": self.cost_high,
            "within_limit_fraction": self.within_limit_fraction,
            "cvar95_cost": self.cvar95_cost,
            "max_cost": self.max_cost,
            "missions": self.missions,
        }

    def key(self, within_limit: bool = True) -> tuple[bool, float, float, int]:
        """The larger the better (module docstring); ``within_limit``: the cost limit comes first."""
        within = self.mean_cost <= self.cost_limit or not within_limit
        return (within, self.mission_success if within else 0.0, -self.mean_cost, -self.epoch)

    def tail_key(self) -> tuple[bool, float, float, float, int]:
        """The tail selection's key, the larger the better: (feasible, success if feasible, within-C fraction,
        -upper bound of the mean cost, epoch); feasible = that upper bound is within C and at least
        TAIL_WITHIN_FRACTION of the UAV-missions are."""
        feasible = self.cost_high <= self.cost_limit and self.within_limit_fraction >= TAIL_WITHIN_FRACTION
        return (
            feasible,
            self.mission_success if feasible else 0.0,
            self.within_limit_fraction,
            -self.cost_high,
            self.epoch,
        )

    def columns(self) -> dict[str, float]:
        """The validation's metrics.csv columns."""
        return {
            "val_mission_success": self.mission_success,
            "val_task_success": self.task_success,
            "val_cost": self.mean_cost,
            "val_cost_high": self.cost_high,
            "val_within_limit": self.within_limit_fraction,
            "val_cvar95_cost": self.cvar95_cost,
            "val_max_cost": self.max_cost,
        }


def score_missions(
    epoch: int, success: np.ndarray, task_done: np.ndarray, role_cost: np.ndarray, cost_limit: float
) -> Score:
    """One role's Score from its missions: success (M,), its task done (M,) and its cost (M,)."""
    high = bootstrap_mean_interval(role_cost).high
    return Score(
        epoch,
        float(success.mean()),
        float(task_done.mean()),
        float(role_cost.mean()),
        cost_limit,
        high,
        within_fraction(role_cost, cost_limit),
        cvar(role_cost),
        float(role_cost.max()),
        int(len(role_cost)),
    )


class EpochSelector:
    """Validates each epoch's checkpoint of one role and keeps the best as ``resume/<role>-best.pt``
    (with ``tail``, also the TAIL_CANDIDATES best as ``resume/<role>-e<epoch>.pt``)."""

    def __init__(
        self,
        scenario: Scenario,
        role: Role,
        out: Path,
        episodes: int,
        seed: int,
        teammates: Mapping[str, PilotSpec],
        mode: ObservationMode,
        within_limit: bool = True,
        tail: bool = False,
    ) -> None:
        self.scenario, self.role, self.episodes, self.mode = scenario, role, episodes, mode
        self.within_limit, self.tail = within_limit, tail
        self.seed = seed
        rng = np.random.default_rng([seed, role.index, SEED_TAG])
        self.layouts = [sample_layout(scenario, rng, protected_starts=False) for _ in range(episodes)]
        self.pilots: list[PilotSpec] = [teammates.get(r.value) if r.index < role.index else GUIDANCE for r in ROLES]
        self.out = out
        self.candidate = out / "resume" / f"{role.value}-last.pt"
        self.best_path = out / "resume" / f"{role.value}-best.pt"
        self.best: Score | None = None
        self.top: list[Score] = []
        """Tail selection: the best TAIL_CANDIDATES screened epochs, best first."""

    def _better(self, a: Score, b: Score) -> bool:
        return a.tail_key() > b.tail_key() if self.tail else a.key(self.within_limit) > b.key(self.within_limit)

    def _fly(self, checkpoint: Path, layouts: list[Layout], epoch: int) -> Score:
        pilots = list(self.pilots)
        pilots[self.role.index] = Policy.load(checkpoint, self.role)
        results = fly_missions(self.scenario, pilots, len(layouts), 0, self.mode, layouts=layouts)
        j = self.role.index
        return score_missions(
            epoch, results.success, results.task_done[:, j], results.cost[:, j], self.scenario.cost_limit
        )

    def _epoch_path(self, epoch: int) -> Path:
        return self.out / "resume" / f"{self.role.value}-e{epoch}.pt"

    def after_epoch(self, epoch: int, write_checkpoint: Callable[[Path], None]) -> dict[str, float]:
        """Write this epoch's checkpoint, validate it, keep it if best; returns the metrics columns."""
        if self.episodes <= 0:
            return {}
        self.candidate.parent.mkdir(parents=True, exist_ok=True)
        write_checkpoint(self.candidate)
        score = self._fly(self.candidate, self.layouts, epoch)
        if self.best is None or self._better(score, self.best):
            _copy_atomic(self.candidate, self.best_path)
            self.best = score
        if self.tail:
            self._keep_candidate(score)
        return {**score.columns(), "best_epoch": self.best.epoch}

    def _keep_candidate(self, score: Score) -> None:
        ranked = sorted([*self.top, score], key=Score.tail_key, reverse=True)
        kept, dropped = ranked[:TAIL_CANDIDATES], ranked[TAIL_CANDIDATES:]
        if any(k is score for k in kept):
            _copy_atomic(self.candidate, self._epoch_path(score.epoch))
        for old in dropped:
            self._epoch_path(old.epoch).unlink(missing_ok=True)
        self.top = kept

    def finish(self, final: Path, write_checkpoint: Callable[[Path], None]) -> Score | None:
        """Ship the best epoch's checkpoint as ``final`` (without validation: the last epoch's)."""
        if self.best is None:
            write_checkpoint(final)
        elif self.tail and self.top:
            self.best = self._final_selection()
            _copy_atomic(self._epoch_path(self.best.epoch), final)
        else:
            _copy_atomic(self.best_path, final)
        return self.best

    def _final_selection(self) -> Score:
        """Fly every candidate on the final selection missions; the best by the tail key on those. Writes
        ``selection-<role>.json`` with both figures of every candidate."""
        rng = np.random.default_rng([self.seed, self.role.index, SEED_TAG, FINAL_TAG])
        layouts = [
            sample_layout(self.scenario, rng, protected_starts=False) for _ in range(self.episodes * TAIL_FINAL_FACTOR)
        ]
        finals = [self._fly(self._epoch_path(s.epoch), layouts, s.epoch) for s in self.top]
        best = max(finals, key=Score.tail_key)
        record = {
            "role": self.role.value,
            "shipped_epoch": best.epoch,
            "candidates": [{"screening": asdict(s), "final": asdict(f)} for s, f in zip(self.top, finals)],
        }
        (self.out / f"selection-{self.role.value}.json").write_text(json.dumps(record, indent=2) + "\n")
        logger.info(
            "%s: tail selection ships epoch %d of %s (final missions: success %.3f, cost %.2f, upper %.2f, "
            "within C %.4f)",
            self.role.value,
            best.epoch,
            [s.epoch for s in self.top],
            best.mission_success,
            best.mean_cost,
            best.cost_high,
            best.within_limit_fraction,
        )
        return best

    def state_dict(self) -> SelectorState:
        return {"best": self.best.state() if self.best else None, "top": [s.state() for s in self.top]}

    def load_state_dict(self, state: SelectorState) -> None:
        best = state.get("best")
        self.best = Score(**best) if best else None
        self.top = [Score(**s) for s in state.get("top", [])]


def _copy_atomic(src: Path, dst: Path) -> None:
    """Copy a checkpoint durably; CheckpointError (one line) if ``src`` does not load: never ship an unreadable file."""
    read_checkpoint(src)
    tmp = dst.with_name(dst.name + ".tmp")
    shutil.copyfile(src, tmp)
    replace_durably(tmp, dst)
