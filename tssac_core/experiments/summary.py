"""Everything ``experiments.json`` holds, as records: per algorithm (grid entry) its seeds' evaluations, the
guidance controller's, and the transfer figures; :meth:`Summary.to_json` writes them.

Figures per algorithm are mean ± sample standard deviation over its finished seeds (:class:`OverSeeds`). The tail
evaluations (``evaluation.tail_episodes``, ``evaluation.generalization_tail_episodes``) are each pooled over an
algorithm's seeds into one sample of missions
(:func:`pooled_tail`, :mod:`tssac_core.common.stats`): success with its 95% Wilson interval, the mean hazard cost
per UAV with its 95% bootstrap interval over missions, the within-C fraction and the tail; with the monitor, the
fraction of flight time under the backup. The transfer speed-up compares, for the detect and strike roles, the learner
decisions (``env_steps`` in metrics.csv) until the first epoch whose task success reaches 90%, TSSAC against
SAC-Lagrangian, and the task success averaged over the role's epochs (which also compares runs that never reach
90%).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, NotRequired, TypedDict, cast

import numpy as np

from tssac_core.common.stats import bootstrap_mean_interval, cvar, wilson_interval, within_fraction
from tssac_core.experiments.evaluations import (
    TAIL_LABELS,
    EvalLabel,
    Evaluations,
    LayoutRule,
    TeamEvaluation,
    eval_specs,
)
from tssac_core.experiments.grid import Grid
from tssac_core.experiments.learning_curves import mean_task_success, read_metrics, steps_to_threshold
from tssac_core.sim.pilots import GUIDANCE
from tssac_core.sim.scenario import ROLES, load
from tssac_core.train.jobs.job import AlgoEntry, Job
from tssac_core.train.wall_time import training_wall_s

PAPER_TABLE4: dict[str, tuple[float, float]] = {
    # Yue et al., Table 4 (section 5.2.2): success rate over 50 random layouts and average cost.
    "ppo": (0.92, 3.8),
    "sac": (0.98, 5.0),
    "cpo": (0.76, 3.0),
    "sac_lag": (0.96, 3.0),
    "tssac": (0.96, 3.0),
}
"""algorithm -> (success rate, average cost) as printed in the paper."""

PAPER_EPOCHS = 50
"""Table 3: epochs per role."""
TRANSFER_THRESHOLD = 0.9
TransferRole = Literal["detect", "strike"]
"""The roles that have a previous role to transfer from."""
TRANSFER_ROLES: tuple[TransferRole, ...] = ("detect", "strike")
TRANSFER_SIDES = ("tssac", "sac_lag")
"""The grid's own curricula compared for the transfer speed-up: with transfer, without."""


# ------------------------------------------------------------------------------ figures over seeds


class OverSeedsJson(TypedDict):
    mean: float | None
    std: float | None
    per_seed: dict[str, float]
    """Seed (as a string) -> its figure."""


@dataclass(frozen=True)
class OverSeeds:
    """Mean and sample standard deviation over seeds (std None with fewer than two; both None with none)."""

    mean: float | None
    std: float | None
    per_seed: dict[int, float]

    def to_json(self) -> OverSeedsJson:
        return {"mean": self.mean, "std": self.std, "per_seed": {str(s): v for s, v in self.per_seed.items()}}


def over_seeds(per_seed: dict[int, float]) -> OverSeeds:
    values = list(per_seed.values())
    return OverSeeds(
        mean=float(np.mean(values)) if values else None,
        std=float(np.std(values, ddof=1)) if len(values) > 1 else None,
        per_seed=dict(per_seed),
    )


def within_limit(evaluation: TeamEvaluation) -> float:
    """The share of UAV-missions (every role of every mission) whose hazard cost is within the scenario's
    limit: how often the constraint held, beside the mean that one long stay inside a radar can dominate."""
    return float(np.mean(evaluation.per_episode.cost <= evaluation.cost_limit))


class CostPoolJson(TypedDict):
    uav_missions: int
    mean: float | None
    ci95: list[float] | None
    over_limit: int
    largest: list[float]


@dataclass(frozen=True)
class CostPool:
    """The mean hazard cost per UAV per mission over every seed's missions pooled (:func:`pooled_cost`)."""

    uav_missions: int
    mean: float | None
    ci95: tuple[float, float] | None
    """95% percentile bootstrap interval over missions."""
    over_limit: int
    """UAV-missions whose cost is over the limit."""
    largest: list[float]
    """The three largest single costs."""

    def to_json(self) -> CostPoolJson:
        return {
            "uav_missions": self.uav_missions,
            "mean": self.mean,
            "ci95": list(self.ci95) if self.ci95 is not None else None,
            "over_limit": self.over_limit,
            "largest": self.largest,
        }


def pooled_cost(evaluations: list[TeamEvaluation]) -> CostPool:
    """The mean hazard cost per UAV per mission over every seed's missions pooled, with a 95% percentile
    bootstrap interval over missions (:func:`tssac_core.common.stats.bootstrap_mean_interval`: a mission's three UAVs
    resampled together, fixed resampling seed), the UAV-missions over the limit and the largest single costs.

    A mean cost near the limit C = 3 is made of rare long stays inside a radar (one of 500-800 steps is
    a whole evaluation's mean of 3-5), so a 50-layout mean alone cannot say on which side of C a policy is;
    the interval says how far the figure can be trusted."""
    if not evaluations:
        return CostPool(uav_missions=0, mean=None, ci95=None, over_limit=0, largest=[])
    costs = np.concatenate([e.per_episode.cost for e in evaluations])  # (M, 3)
    mean = bootstrap_mean_interval(costs)
    limit = evaluations[0].cost_limit
    return CostPool(
        uav_missions=int(costs.size),
        mean=float(costs.mean()),
        ci95=(mean.low, mean.high),
        over_limit=int((costs > limit).sum()),
        largest=sorted(costs.ravel().tolist(), reverse=True)[:3],
    )


# ------------------------------------------------------------------------------------- the tail


@dataclass(frozen=True)
class TailFigures:
    """A pooled sample of missions' figures (:func:`pooled_tail`)."""

    success_rate: float
    success_interval95: tuple[float, float]
    """95% Wilson score interval."""
    mean_cost: float
    """Hazard cost per UAV per mission."""
    mean_cost_interval95: tuple[float, float]
    """95% bootstrap interval over missions."""
    within_cost_limit: float
    """Share of UAV-missions whose cost is at most C."""
    within_cost_limit_per_role: dict[str, float]
    """Per role (in the order of ``ROLES``), the share of its UAV-missions whose cost is at most C."""
    over_limit: int
    cvar95_cost: float
    largest: list[float]
    left_area: int
    """UAVs that left the area."""
    tasks_finished: dict[str, int] | None = None
    """Per role, the missions in which that role finished its task (None unless every evaluation says)."""


@dataclass(frozen=True)
class MonitorFigures:
    """A pooled sample's figures when it was flown with the runtime-assurance monitor."""

    backup_time_fraction: float
    interventions_per_uav_mission: float


class TailPoolJson(TypedDict):
    """:class:`TailPool` in ``experiments.json``: the counts, then :class:`TailFigures`' fields if there are
    missions, then :class:`MonitorFigures`' if every evaluation was flown with the monitor."""

    missions: int
    seeds: int
    success_rate: NotRequired[float]
    success_interval95: NotRequired[list[float]]
    mean_cost: NotRequired[float]
    mean_cost_interval95: NotRequired[list[float]]
    within_cost_limit: NotRequired[float]
    within_cost_limit_per_role: NotRequired[dict[str, float]]
    over_limit: NotRequired[int]
    cvar95_cost: NotRequired[float]
    largest: NotRequired[list[float]]
    left_area: NotRequired[int]
    tasks_finished: NotRequired[dict[str, int] | None]
    backup_time_fraction: NotRequired[float]
    interventions_per_uav_mission: NotRequired[float]


@dataclass(frozen=True)
class TailPool:
    """The tail evaluations of an algorithm's seeds pooled into one sample of missions."""

    missions: int
    seeds: int
    figures: TailFigures | None
    """None without missions."""
    monitor: MonitorFigures | None
    """None unless every pooled evaluation was flown with the monitor."""

    def to_json(self) -> TailPoolJson:
        out: TailPoolJson = {"missions": self.missions, "seeds": self.seeds}
        if (f := self.figures) is not None:
            out["success_rate"] = f.success_rate
            out["success_interval95"] = list(f.success_interval95)
            out["mean_cost"] = f.mean_cost
            out["mean_cost_interval95"] = list(f.mean_cost_interval95)
            out["within_cost_limit"] = f.within_cost_limit
            out["within_cost_limit_per_role"] = dict(f.within_cost_limit_per_role)
            out["over_limit"] = f.over_limit
            out["cvar95_cost"] = f.cvar95_cost
            out["largest"] = list(f.largest)
            out["left_area"] = f.left_area
            out["tasks_finished"] = dict(f.tasks_finished) if f.tasks_finished is not None else None
        if (m := self.monitor) is not None:
            out["backup_time_fraction"] = m.backup_time_fraction
            out["interventions_per_uav_mission"] = m.interventions_per_uav_mission
        return out


def pooled_tail(evaluations: list[TeamEvaluation]) -> TailPool:
    """The tail evaluations of an algorithm's seeds pooled into one sample of missions (:mod:`tssac_core.common.stats`):
    success k of n with its 95% Wilson interval; the mean hazard cost per UAV with its 95% bootstrap interval over
    missions (a mission's three UAVs resampled together); the within-C fraction of the UAV-missions, all and per role,
    how many are over C, their CVaR at 95% and the largest costs; the UAVs that left the area; and, for evaluations
    flown with the monitor, the fraction of flight time under the backup and the interventions per UAV-mission."""
    if not evaluations:
        return TailPool(missions=0, seeds=0, figures=None, monitor=None)
    per = [e.per_episode for e in evaluations]
    success = np.concatenate([p.success for p in per])
    cost = np.concatenate([p.cost for p in per])  # (M, 3)
    limit = evaluations[0].cost_limit
    rate, mean = wilson_interval(int(success.sum()), int(success.size)), bootstrap_mean_interval(cost)
    left_area = 0
    for p in per:
        if p.out_of_area is None:
            raise ValueError("a tail evaluation without out_of_area")
        left_area += int(p.out_of_area.sum())
    figures = TailFigures(
        success_rate=rate.value,
        success_interval95=(rate.low, rate.high),
        mean_cost=mean.value,
        mean_cost_interval95=(mean.low, mean.high),
        within_cost_limit=within_fraction(cost, limit),
        within_cost_limit_per_role={role.value: within_fraction(cost[:, j], limit) for j, role in enumerate(ROLES)},
        over_limit=int((cost > limit).sum()),
        cvar95_cost=cvar(cost),
        largest=sorted(cost.ravel().tolist(), reverse=True)[:3],
        left_area=left_area,
        tasks_finished=_pooled_tasks(evaluations),
    )
    counts = [p.monitor for p in per if p.monitor is not None]
    monitor = None
    if len(counts) == len(per):
        backup = sum(float(np.sum(c.backup_steps)) for c in counts)
        flown = sum(float(np.sum(c.flown_steps)) for c in counts)
        monitor = MonitorFigures(
            backup_time_fraction=backup / max(1.0, flown),
            interventions_per_uav_mission=float(np.concatenate([c.interventions for c in counts]).mean()),
        )
    return TailPool(missions=int(success.size), seeds=len(evaluations), figures=figures, monitor=monitor)


def _pooled_tasks(evaluations: list[TeamEvaluation]) -> dict[str, int] | None:
    """Per role, the pooled missions in which it finished its task; None if an evaluation does not say."""
    counts: dict[str, int] = {}
    for e in evaluations:
        if e.tasks_finished is None:
            return None
        for role, k in e.tasks_finished.items():
            counts[role] = counts.get(role, 0) + k
    return counts


class SeedFiguresJson(TypedDict):
    success_rate: float
    mean_cost: float


@dataclass(frozen=True)
class SeedFigures:
    success_rate: float
    mean_cost: float

    def to_json(self) -> SeedFiguresJson:
        return {"success_rate": self.success_rate, "mean_cost": self.mean_cost}


class TailRowJson(TailPoolJson):
    """:class:`TailRow` in ``experiments.json``: its pool's figures, then which seeds were flown and theirs."""

    flown_seeds: list[int]
    per_seed: dict[str, SeedFiguresJson]


@dataclass(frozen=True)
class TailRow:
    """An algorithm's tail column: its seeds' evaluations pooled, which seeds were flown, and each seed's figures."""

    pool: TailPool
    flown_seeds: list[int]
    per_seed: dict[int, SeedFigures]

    def to_json(self) -> TailRowJson:
        return {
            **self.pool.to_json(),
            "flown_seeds": self.flown_seeds,
            "per_seed": {str(s): f.to_json() for s, f in self.per_seed.items()},
        }


def tail_row(jobs: list[Job], label: EvalLabel, evaluations: Evaluations) -> TailRow:
    """The tail column of an algorithm's finished ``jobs``: those whose ``label`` evaluation is there, pooled."""
    flown = [(j.seed, evaluations[(j.name, label)]) for j in jobs if (j.name, label) in evaluations]
    return TailRow(
        pool=pooled_tail([e for _, e in flown]),
        flown_seeds=[s for s, _ in flown],
        per_seed={s: SeedFigures(e.success_rate, e.mean_cost) for s, e in flown},
    )


# ----------------------------------------------------------------------------- rows per algorithm


class EvalRowJson(TypedDict):
    success_rate: OverSeedsJson
    mean_cost: OverSeedsJson
    within_cost_limit: OverSeedsJson
    pooled_cost: CostPoolJson


@dataclass(frozen=True)
class EvalRow:
    """An algorithm's figures on one of the 50-layout evaluations (Table 4, figure 11)."""

    success_rate: OverSeeds
    mean_cost: OverSeeds
    within_cost_limit: OverSeeds
    pooled_cost: CostPool

    def to_json(self) -> EvalRowJson:
        return {
            "success_rate": self.success_rate.to_json(),
            "mean_cost": self.mean_cost.to_json(),
            "within_cost_limit": self.within_cost_limit.to_json(),
            "pooled_cost": self.pooled_cost.to_json(),
        }


def eval_row(jobs: list[Job], label: EvalLabel, evaluations: Evaluations) -> EvalRow:
    mine = [(j.seed, evaluations[(j.name, label)]) for j in jobs]
    return EvalRow(
        success_rate=over_seeds({s: e.success_rate for s, e in mine}),
        mean_cost=over_seeds({s: e.mean_cost for s, e in mine}),
        within_cost_limit=over_seeds({s: within_limit(e) for s, e in mine}),
        pooled_cost=pooled_cost([e for _, e in mine]),
    )


@dataclass(frozen=True)
class PaperFigures:
    """The paper's Table 4 row."""

    success_rate: float
    mean_cost: float

    def to_json(self) -> SeedFiguresJson:
        return {"success_rate": self.success_rate, "mean_cost": self.mean_cost}


TailField = Literal["tail", "tail_monitor", "generalization_tail"]

TAIL_FIELDS: dict[EvalLabel, TailField] = {
    EvalLabel.TAIL: "tail",
    EvalLabel.TAIL_MONITOR: "tail_monitor",
    EvalLabel.GENERALIZATION_TAIL: "generalization_tail",
}
"""The field of :class:`AlgorithmSummary` and :class:`GuidanceSummary` that holds each tail evaluation."""


class _TailRowsJson(TypedDict, total=False):
    tail: TailRowJson
    tail_monitor: TailRowJson
    generalization_tail: TailRowJson


class _GeneralizationJson(TypedDict, total=False):
    generalization: EvalRowJson


class AlgorithmSummaryJson(TypedDict):
    """:class:`AlgorithmSummary` in ``experiments.json`` (the tails after ``seeds``, if the grid flies them)."""

    name: str
    algo: str
    penalty: float
    seeds: list[int]
    tail: NotRequired[TailRowJson]
    tail_monitor: NotRequired[TailRowJson]
    generalization_tail: NotRequired[TailRowJson]
    random: EvalRowJson
    generalization: NotRequired[EvalRowJson]
    training_wall_s: OverSeedsJson
    paper: SeedFiguresJson | None


@dataclass(frozen=True)
class AlgorithmSummary:
    """One grid entry's row: its finished seeds and their figures."""

    name: str
    algo: str
    penalty: float
    seeds: list[int]
    """The finished seeds."""
    random: EvalRow
    """Table 4's layouts."""
    training_wall_s: OverSeeds
    """Training wall seconds per seed (:mod:`tssac_core.train.wall_time`), of the seeds that recorded it."""
    paper: PaperFigures | None
    """The paper's figures for this algorithm (none for SAC with a hazard penalty)."""
    generalization: EvalRow | None = None
    tail: TailRow | None = None
    tail_monitor: TailRow | None = None
    generalization_tail: TailRow | None = None

    def tail_of(self, label: EvalLabel) -> TailRow | None:
        """The row of the tail evaluation ``label`` (None: the grid does not fly it)."""
        return cast(TailRow | None, getattr(self, TAIL_FIELDS[label]))

    def to_json(self) -> AlgorithmSummaryJson:
        tails: _TailRowsJson = {}
        for label in TAIL_LABELS:
            if (tail := self.tail_of(label)) is not None:
                tails[TAIL_FIELDS[label]] = tail.to_json()
        generalization: _GeneralizationJson = {}
        if self.generalization is not None:
            generalization["generalization"] = self.generalization.to_json()
        return {
            "name": self.name,
            "algo": self.algo,
            "penalty": self.penalty,
            "seeds": self.seeds,
            **tails,
            "random": self.random.to_json(),
            **generalization,
            "training_wall_s": self.training_wall_s.to_json(),
            "paper": self.paper.to_json() if self.paper is not None else None,
        }


class GuidanceRowJson(TypedDict):
    success_rate: float
    mean_cost: float
    episodes: int
    within_cost_limit: float


@dataclass(frozen=True)
class GuidanceRow:
    """The guidance controller on one of the 50-layout evaluations."""

    success_rate: float
    mean_cost: float
    episodes: int
    within_cost_limit: float

    def to_json(self) -> GuidanceRowJson:
        return {
            "success_rate": self.success_rate,
            "mean_cost": self.mean_cost,
            "episodes": self.episodes,
            "within_cost_limit": self.within_cost_limit,
        }


class GuidanceSummaryJson(TypedDict):
    random: GuidanceRowJson
    generalization: NotRequired[GuidanceRowJson]
    tail: NotRequired[TailPoolJson]
    tail_monitor: NotRequired[TailPoolJson]
    generalization_tail: NotRequired[TailPoolJson]


@dataclass(frozen=True)
class GuidanceSummary:
    """The guidance controller's figures: the reference row."""

    random: GuidanceRow
    generalization: GuidanceRow | None = None
    tail: TailPool | None = None
    tail_monitor: TailPool | None = None
    generalization_tail: TailPool | None = None

    def tail_of(self, label: EvalLabel) -> TailPool | None:
        """The tail evaluation ``label`` (None: the grid does not fly it)."""
        return cast(TailPool | None, getattr(self, TAIL_FIELDS[label]))

    def to_json(self) -> GuidanceSummaryJson:
        out: GuidanceSummaryJson = {"random": self.random.to_json()}
        if self.generalization is not None:
            out["generalization"] = self.generalization.to_json()
        for label in TAIL_LABELS:
            if (tail := self.tail_of(label)) is not None:
                out[TAIL_FIELDS[label]] = tail.to_json()
        return out


def algorithm_summary(
    entry: AlgoEntry, jobs: list[Job], labels: Sequence[EvalLabel], evaluations: Evaluations
) -> AlgorithmSummary:
    """The row of one grid entry from its finished ``jobs`` (``labels``: the grid's evaluations)."""
    rows = {label: eval_row(jobs, label, evaluations) for label in labels if not label.is_tail}
    tails = {label: tail_row(jobs, label, evaluations) for label in labels if label.is_tail}
    walls = {j.seed: w for j in jobs if (w := training_wall_s(j.out)) is not None}
    paper = PAPER_TABLE4.get(entry.algo) if entry.algo != "sac_penalty" else None
    return AlgorithmSummary(
        name=entry.name,
        algo=entry.algo,
        penalty=entry.penalty,
        seeds=[j.seed for j in jobs],
        random=rows[EvalLabel.RANDOM],
        training_wall_s=over_seeds(walls),
        paper=PaperFigures(*paper) if paper else None,
        generalization=rows.get(EvalLabel.GENERALIZATION),
        tail=tails.get(EvalLabel.TAIL),
        tail_monitor=tails.get(EvalLabel.TAIL_MONITOR),
        generalization_tail=tails.get(EvalLabel.GENERALIZATION_TAIL),
    )


def guidance_summary(labels: Sequence[EvalLabel], evaluations: Evaluations) -> GuidanceSummary:
    """The guidance controller's row: its 50-layout figures, and its tail evaluations if they are there."""

    def row(label: EvalLabel) -> GuidanceRow | None:
        if label not in labels:
            return None
        e = evaluations[(GUIDANCE, label)]
        return GuidanceRow(e.success_rate, e.mean_cost, e.episodes, within_limit(e))

    def tail(label: EvalLabel) -> TailPool | None:
        if label not in labels:
            return None
        return pooled_tail([evaluations[(GUIDANCE, label)]] if (GUIDANCE, label) in evaluations else [])

    random = row(EvalLabel.RANDOM)
    assert random is not None, "every grid flies its evaluation scenario"
    return GuidanceSummary(
        random=random,
        generalization=row(EvalLabel.GENERALIZATION),
        tail=tail(EvalLabel.TAIL),
        tail_monitor=tail(EvalLabel.TAIL_MONITOR),
        generalization_tail=tail(EvalLabel.GENERALIZATION_TAIL),
    )


# ----------------------------------------------------------------------------------- transfer


class StepsFiguresJson(TypedDict):
    entry: str | None
    per_seed: dict[str, int | None]
    counted: dict[str, int]
    seeds: int
    reached: int
    mean_steps: float | None
    mean_is_lower_bound: bool
    mean_task_success: OverSeedsJson


@dataclass(frozen=True)
class StepsFigures:
    """Decisions until a role first reached a task-success level in each run of one side, and their mean."""

    entry: str | None
    """The grid entry (None if the grid has none for this side)."""
    per_seed: dict[int, int | None]
    """Decisions at the end of the first epoch at the level; None: never reached."""
    counted: dict[int, int]
    """What each seed counts in the mean: its decisions to the level, or all its decisions (a lower bound)."""
    seeds: int
    reached: int
    mean_steps: float | None
    mean_is_lower_bound: bool
    """Some seed never reached the level: the mean counts its total decisions."""
    mean_task_success: OverSeeds
    """Task success in training averaged over the role's epochs (the area under its learning curve)."""

    def to_json(self) -> StepsFiguresJson:
        return {
            "entry": self.entry,
            "per_seed": {str(s): v for s, v in self.per_seed.items()},
            "counted": {str(s): v for s, v in self.counted.items()},
            "seeds": self.seeds,
            "reached": self.reached,
            "mean_steps": self.mean_steps,
            "mean_is_lower_bound": self.mean_is_lower_bound,
            "mean_task_success": self.mean_task_success.to_json(),
        }


def steps_figures(jobs: list[Job], role: str, threshold: float, entry: str | None) -> StepsFigures:
    """Decisions until ``role`` first reached ``threshold`` task success in each run, and their mean over seeds.

    A seed that never reached it counts with its role's total decisions, a lower bound of what it would have
    needed; the mean is then marked as a lower bound.
    """
    per_seed: dict[int, int | None] = {}
    counted: dict[int, int] = {}
    mean_task: dict[int, float] = {}
    for job in jobs:
        rows = read_metrics(job.out)
        reached, total = steps_to_threshold(rows, role, threshold)
        per_seed[job.seed] = reached
        counted[job.seed] = reached if reached is not None else total
        mean_task[job.seed] = mean_task_success(rows, role)
    return StepsFigures(
        entry=entry,
        per_seed=per_seed,
        counted=counted,
        seeds=len(jobs),
        reached=sum(v is not None for v in per_seed.values()),
        mean_steps=float(np.mean(list(counted.values()))) if counted else None,
        mean_is_lower_bound=any(v is None for v in per_seed.values()),
        mean_task_success=over_seeds(mean_task),
    )


class SpeedupRoleJson(TypedDict):
    """A role in ``transfer_speedup``: the sides named by their algorithm (:data:`TRANSFER_SIDES`)."""

    tssac: StepsFiguresJson
    sac_lag: StepsFiguresJson
    speedup: float | None
    speedup_is_lower_bound: bool


TransferRoleJson = TypedDict(
    "TransferRoleJson",
    {"with": StepsFiguresJson, "without": StepsFiguresJson, "speedup": float | None, "speedup_is_lower_bound": bool},
)
"""A role in ``transfer_experiment``: the sides named with and without."""


@dataclass(frozen=True)
class RoleComparison:
    """One role's decisions to the level with transfer and without, and the speed-up (:func:`compare`)."""

    with_transfer: StepsFigures
    without_transfer: StepsFigures
    speedup: float | None
    """Mean decisions without transfer over those with it; None when the with-transfer mean is a lower bound (the
    ratio then bounds nothing) or there is nothing to compare."""
    speedup_is_lower_bound: bool
    """Only the without-transfer mean is a lower bound."""

    def by_algorithm(self) -> SpeedupRoleJson:
        """As ``transfer_speedup`` writes it: with transfer is TSSAC, without is SAC-Lagrangian."""
        return {
            "tssac": self.with_transfer.to_json(),
            "sac_lag": self.without_transfer.to_json(),
            "speedup": self.speedup,
            "speedup_is_lower_bound": self.speedup_is_lower_bound,
        }

    def with_without(self) -> TransferRoleJson:
        """As ``transfer_experiment`` writes it."""
        return {
            "with": self.with_transfer.to_json(),
            "without": self.without_transfer.to_json(),
            "speedup": self.speedup,
            "speedup_is_lower_bound": self.speedup_is_lower_bound,
        }


def compare(fast: StepsFigures, slow: StepsFigures) -> RoleComparison:
    """``slow``'s mean decisions over ``fast``'s; a lower bound when only ``slow``'s mean is one."""
    ratio = None
    if fast.mean_steps and slow.mean_steps is not None and not fast.mean_is_lower_bound:
        ratio = slow.mean_steps / fast.mean_steps
    return RoleComparison(fast, slow, ratio, ratio is not None and slow.mean_is_lower_bound)


class TransferSpeedupJson(TypedDict):
    threshold: float
    detect: NotRequired[SpeedupRoleJson]
    strike: NotRequired[SpeedupRoleJson]


@dataclass(frozen=True)
class TransferSpeedup:
    """Transfer inside the grid's own curricula: per role, TSSAC (with) against SAC-Lagrangian (without)."""

    threshold: float
    roles: dict[TransferRole, RoleComparison]

    def to_json(self) -> TransferSpeedupJson:
        out: TransferSpeedupJson = {"threshold": self.threshold}
        for role, r in self.roles.items():
            out[role] = r.by_algorithm()
        return out


def transfer_speedup(grid: Grid, finished: list[Job]) -> TransferSpeedup:
    """Decisions until >= 90% task success in the grid's own curricula, TSSAC vs SAC-Lagrangian, per role
    (mean over finished seeds; :func:`steps_figures`, :func:`compare`)."""
    roles: dict[TransferRole, RoleComparison] = {}
    for role in TRANSFER_ROLES:
        sides = []
        for algo in TRANSFER_SIDES:
            entry = next((e for e in grid.algos if e.algo == algo), None)
            jobs = [j for j in finished if entry is not None and j.entry == entry]
            sides.append(steps_figures(jobs, role, TRANSFER_THRESHOLD, entry.name if entry is not None else None))
        roles[role] = compare(*sides)
    return TransferSpeedup(TRANSFER_THRESHOLD, roles)


class TransferFiguresJson(TypedDict):
    threshold: float
    teammates: str
    epochs: int
    steps_per_epoch: int
    roles: list[str]
    detect: NotRequired[TransferRoleJson]
    strike: NotRequired[TransferRoleJson]


def transfer_role(role: str) -> TransferRole:
    """``role`` as one of the roles transfer is measured for (the grid's reader allows no other)."""
    if role == "detect":
        return "detect"
    if role == "strike":
        return "strike"
    raise ValueError(f"no transfer into the {role} role")


@dataclass(frozen=True)
class TransferFigures:
    """The transfer experiment's figures (``grid.transfer``): per role, both sides' decisions to the level."""

    threshold: float
    teammates: str
    epochs: int
    steps_per_epoch: int
    roles: tuple[TransferRole, ...]
    per_role: dict[TransferRole, RoleComparison]

    def to_json(self) -> TransferFiguresJson:
        out: TransferFiguresJson = {
            "threshold": self.threshold,
            "teammates": self.teammates,
            "epochs": self.epochs,
            "steps_per_epoch": self.steps_per_epoch,
            "roles": list(self.roles),
        }
        for role, r in self.per_role.items():
            out[role] = r.with_without()
        return out


def transfer_experiment(grid: Grid, runs: list[Job]) -> TransferFigures | None:
    """The transfer experiment's figures (``grid.transfer``) from its finished runs: per role, the decisions
    to the level with transfer and without, and the speed-up. None if the grid has no such experiment."""
    t = grid.transfer
    if t is None:
        return None
    roles = tuple(transfer_role(role) for role in t.roles)
    per_role: dict[TransferRole, RoleComparison] = {}
    for role in roles:
        sides = []
        for entry in (t.with_transfer, t.without_transfer):
            jobs = [j for j in runs if j.role == role and j.entry == entry]
            sides.append(steps_figures(jobs, role, t.task_success, jobs[0].entry.name if jobs else None))
        per_role[role] = compare(*sides)
    return TransferFigures(
        threshold=t.task_success,
        teammates=shown(t.teammates),
        epochs=t.epochs,
        steps_per_epoch=grid.train.steps_per_epoch,
        roles=roles,
        per_role=per_role,
    )


# ------------------------------------------------------------------------------------- the whole


class EvaluationInfoJson(TypedDict):
    scenario: str
    episodes: int
    seed: int
    generalization_scenario: str | None
    tail_episodes: int | None
    tail_seed: int | None
    tail_monitor: bool | None
    layouts: str
    tail_layouts: str | None
    generalization_tail_episodes: int | None
    generalization_tail_seed: int | None


@dataclass(frozen=True)
class EvaluationInfo:
    """How the teams were flown (the grid's ``evaluation:``), as paths a user of the results would write."""

    scenario: str
    episodes: int
    seed: int
    generalization_scenario: str | None
    tail_episodes: int | None
    tail_seed: int | None
    tail_monitor: bool | None
    layouts: str
    """How the 50-layout evaluations draw their layouts (LayoutRule.IN_TURN)."""
    tail_layouts: str | None
    """How the tails draw theirs (LayoutRule.PER_MISSION); None without a tail."""
    generalization_tail_episodes: int | None
    generalization_tail_seed: int | None

    def to_json(self) -> EvaluationInfoJson:
        return {
            "scenario": self.scenario,
            "episodes": self.episodes,
            "seed": self.seed,
            "generalization_scenario": self.generalization_scenario,
            "tail_episodes": self.tail_episodes,
            "tail_seed": self.tail_seed,
            "tail_monitor": self.tail_monitor,
            "layouts": self.layouts,
            "tail_layouts": self.tail_layouts,
            "generalization_tail_episodes": self.generalization_tail_episodes,
            "generalization_tail_seed": self.generalization_tail_seed,
        }


class TrainingBudgetJson(TypedDict):
    epochs_per_role: int
    steps_per_epoch: int
    action_repeat: int
    paper_epochs_per_role: int


@dataclass(frozen=True)
class TrainingBudget:
    epochs_per_role: int
    steps_per_epoch: int
    action_repeat: int
    paper_epochs_per_role: int

    def to_json(self) -> TrainingBudgetJson:
        return {
            "epochs_per_role": self.epochs_per_role,
            "steps_per_epoch": self.steps_per_epoch,
            "action_repeat": self.action_repeat,
            "paper_epochs_per_role": self.paper_epochs_per_role,
        }


class SummaryJson(TypedDict):
    """``experiments.json``."""

    grid: str
    results: str
    evaluation: EvaluationInfoJson
    training: TrainingBudgetJson
    cost_limit: float
    algorithms: list[AlgorithmSummaryJson]
    guidance: GuidanceSummaryJson
    transfer_speedup: TransferSpeedupJson
    transfer_experiment: TransferFiguresJson | None
    left_out: list[str]


@dataclass(frozen=True)
class Summary:
    """Everything ``experiments.json`` holds."""

    grid: str
    results: str
    evaluation: EvaluationInfo
    training: TrainingBudget
    cost_limit: float
    algorithms: dict[str, AlgorithmSummary]
    """Grid entry name -> its row, in the grid's order."""
    guidance: GuidanceSummary
    transfer_speedup: TransferSpeedup
    transfer_experiment: TransferFigures | None
    left_out: list[str]
    """The grid's jobs not reported (not finished, or run with other settings)."""

    def to_json(self) -> SummaryJson:
        return {
            "grid": self.grid,
            "results": self.results,
            "evaluation": self.evaluation.to_json(),
            "training": self.training.to_json(),
            "cost_limit": self.cost_limit,
            "algorithms": [a.to_json() for a in self.algorithms.values()],
            "guidance": self.guidance.to_json(),
            "transfer_speedup": self.transfer_speedup.to_json(),
            "transfer_experiment": (
                self.transfer_experiment.to_json() if self.transfer_experiment is not None else None
            ),
            "left_out": self.left_out,
        }


def summarise(
    grid: Grid,
    jobs: list[Job],
    finished: list[Job],
    evaluations: Evaluations,
    results: Path,
    transfer_runs: Sequence[Job] = (),
) -> Summary:
    """The summary of the grid's ``finished`` jobs (of ``jobs``) and their ``evaluations``."""
    labels = [spec.label for spec in eval_specs(grid)]
    ev = grid.evaluation
    return Summary(
        grid=shown(grid.source),
        results=shown(results),
        evaluation=EvaluationInfo(
            scenario=shown(ev.scenario),
            episodes=ev.episodes,
            seed=ev.seed,
            generalization_scenario=shown(ev.generalization_scenario) if ev.generalization_scenario else None,
            tail_episodes=ev.tail_episodes,
            tail_seed=ev.tail_seed if ev.tail_episodes else None,
            tail_monitor=ev.tail_monitor if ev.tail_episodes else None,
            layouts=LayoutRule.IN_TURN.value,
            tail_layouts=LayoutRule.PER_MISSION.value if ev.tail_episodes or ev.generalization_tail_episodes else None,
            generalization_tail_episodes=ev.generalization_tail_episodes,
            generalization_tail_seed=ev.generalization_tail_seed if ev.generalization_tail_episodes else None,
        ),
        training=TrainingBudget(
            epochs_per_role=grid.train.epochs,
            steps_per_epoch=grid.train.steps_per_epoch,
            action_repeat=grid.train.action_repeat,
            paper_epochs_per_role=PAPER_EPOCHS,
        ),
        cost_limit=load(ev.scenario).cost_limit,
        algorithms={
            entry.name: algorithm_summary(entry, [j for j in finished if j.entry == entry], labels, evaluations)
            for entry in grid.algos
        },
        guidance=guidance_summary(labels, evaluations),
        transfer_speedup=transfer_speedup(grid, finished),
        transfer_experiment=transfer_experiment(grid, list(transfer_runs)),
        left_out=[j.name for j in jobs if j not in finished],
    )


def shown(path: Path) -> str:
    """A path as a user of this directory would write it: relative to the working directory if inside it."""
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)
