"""The grid's evaluations: what every team flies, and the cache that keeps each flight beside its team.

Every finished team, and the guidance controller as a reference row, flies the evaluation scenario's layouts
drawn from the grid's evaluation seed (the same layouts for every team), and the generalisation scenario's if the
grid names one. With ``evaluation.tail_episodes`` (issue 23) every team also flies that many more layouts (e.g.
500, their own seed), and with ``tail_monitor`` the same layouts a second time through the runtime-assurance
monitor (issue 24, ``evaluate --shield``); with ``evaluation.generalization_tail_episodes``, that many layouts of
the generalisation scenario (their own seed, no monitor). These three are the tails: many layouts, one seed per
mission (LayoutRule.PER_MISSION), pooled over an algorithm's seeds in the report.

Each evaluation is cached as JSON next to the team (``<run>/eval_random.json``, ``eval_generalization.json``,
``eval_tail.json``, ``eval_tail_monitor.json``, ``eval_generalization_tail.json``; the guidance controller's under
``<results>/guidance/``): the keys
of ``tssac_core.evaluate --json`` plus ``per_episode``, the per-mission figures the box plots and the pooled
intervals need. A cache is reused only if it was made from the same checkpoints, scenario, seed, number of
episodes and layout rule (and monitor settings), so an interrupted report flies only what is missing when it runs
again. :class:`TeamEvaluation` is what the report reads of a cache file.
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NotRequired, TypedDict

import numpy as np

from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.common.cli import write_json
from tssac_core.common.evaluation_record import BatchedRun, EvaluationRecord, RecordError
from tssac_core.deploy.manifest import check_models, warn_once
from tssac_core.experiments.grid import Grid
from tssac_core.sim.missions import MissionResults, fly_missions
from tssac_core.sim.pilots import GUIDANCE, PilotSpec
from tssac_core.sim.scenario import ROLES, Layout, Scenario, load, sample_layout
from tssac_core.train.jobs.job import Job


class EvalLabel(enum.Enum):
    """Which of the grid's evaluations; names the cache file (``eval_<label>.json``)."""

    RANDOM = "random"
    """Table 4 and figure 10: the evaluation scenario's layouts."""
    GENERALIZATION = "generalization"
    """Figure 11: the generalisation scenario's layouts."""
    TAIL = "tail"
    """The many-layout columns: ``tail_episodes`` more layouts of the evaluation scenario."""
    TAIL_MONITOR = "tail_monitor"
    """The same layouts flown through the runtime-assurance monitor."""
    GENERALIZATION_TAIL = "generalization_tail"
    """``generalization_tail_episodes`` layouts of the generalisation scenario."""

    @property
    def is_tail(self) -> bool:
        """Many layouts, one seed per mission, pooled over seeds (:data:`TAIL_LABELS`)."""
        return self in TAIL_LABELS


TAIL_LABELS = (EvalLabel.TAIL, EvalLabel.TAIL_MONITOR, EvalLabel.GENERALIZATION_TAIL)
"""The tail evaluations, in the order the grid flies them."""


class LayoutRule(enum.Enum):
    """How an evaluation's M layouts come from its seed S."""

    IN_TURN = "drawn in turn from one generator seeded S"
    """Table 4's 50 layouts and figure 11's, as every table of this grid has flown them (the rule of
    ``tssac_core.evaluate`` before each mission had its own seed): kept, so that the paper's protocol flies the
    same layouts as before and its cached evaluations stand."""
    PER_MISSION = "mission k: layout seed S + k"
    """The tails' layouts: ``tssac_core.sim.missions.mission_layout``, as ``tssac_core.evaluate`` and
    ``mavlink_bridge.fly`` draw them now, so that ``evaluate --seed S --mission k`` flies any one of them again."""


def layouts_in_turn(scenario: Scenario, episodes: int, seed: int) -> list[Layout]:
    """``episodes`` layouts drawn one after another from one generator seeded ``seed`` (LayoutRule.IN_TURN)."""
    rng = np.random.default_rng(seed)
    return [sample_layout(scenario, rng) for _ in range(episodes)]


@dataclass(frozen=True)
class EvalSpec:
    """One evaluation every team flies."""

    label: EvalLabel
    scenario: Path
    episodes: int
    seed: int
    monitor: bool = False
    """Fly every UAV through the runtime-assurance monitor (``evaluate --shield``, its default margins)."""
    layouts: LayoutRule = LayoutRule.IN_TURN

    def cache_name(self) -> str:
        return f"eval_{self.label.value}.json"


def eval_specs(grid: Grid) -> list[EvalSpec]:
    """What every team flies: the evaluation scenario's layouts, then those the grid's ``evaluation:`` adds (the
    generalisation scenario's, the tail, the tail with the monitor, the generalisation tail)."""
    ev = grid.evaluation
    specs = [EvalSpec(EvalLabel.RANDOM, ev.scenario, ev.episodes, ev.seed)]
    if ev.generalization_scenario is not None:
        specs.append(EvalSpec(EvalLabel.GENERALIZATION, ev.generalization_scenario, ev.episodes, ev.seed))
    if ev.tail_episodes is not None:
        tail = EvalSpec(EvalLabel.TAIL, ev.scenario, ev.tail_episodes, ev.tail_seed, layouts=LayoutRule.PER_MISSION)
        specs.append(tail)
        if ev.tail_monitor:
            specs.append(dataclasses.replace(tail, label=EvalLabel.TAIL_MONITOR, monitor=True))
    if ev.generalization_tail_episodes is not None:
        assert ev.generalization_scenario is not None, "the grid file's reader requires it"
        specs.append(
            EvalSpec(
                EvalLabel.GENERALIZATION_TAIL,
                ev.generalization_scenario,
                ev.generalization_tail_episodes,
                ev.generalization_tail_seed,
                layouts=LayoutRule.PER_MISSION,
            )
        )
    return specs


@dataclass(frozen=True)
class MonitorPerEpisode:
    """The runtime-assurance monitor's counts per UAV-mission, (M, 3) each."""

    backup_steps: np.ndarray
    flown_steps: np.ndarray
    interventions: np.ndarray


PerEpisodeJson = TypedDict(
    "PerEpisodeJson",
    {
        "success": list[bool],
        "cost": list[list[float]],
        "return": NotRequired[list[list[float]]],
        "out_of_area": NotRequired[list[list[bool]]],
        "backup_steps": NotRequired[list[list[float]]],
        "flown_steps": NotRequired[list[list[float]]],
        "interventions": NotRequired[list[list[float]]],
    },
)
"""A cache file's ``per_episode`` (:func:`evaluate`): per mission, and per role where a list of lists; ``return`` for
the 50-layout evaluations, ``out_of_area`` for the tails, the counts with the monitor. (Functional syntax: ``return``
is a keyword.)"""


@dataclass(frozen=True)
class PerEpisode:
    """One evaluation's figures per mission: M missions, three roles."""

    success: np.ndarray
    """(M,) bool: the target was hit."""
    cost: np.ndarray
    """(M, 3) hazard cost per role."""
    returns: np.ndarray | None
    """(M, 3) return per role: the 50-layout evaluations (the box plots), not the tails'."""
    out_of_area: np.ndarray | None
    """(M, 3) bool: the UAV left the area; the tails'."""
    monitor: MonitorPerEpisode | None
    """With the monitor: its counts."""

    @classmethod
    def from_record(cls, data: PerEpisodeJson) -> PerEpisode:
        """From a cache file's ``per_episode``."""
        monitor = None
        if "backup_steps" in data:
            monitor = MonitorPerEpisode(
                np.asarray(data["backup_steps"], dtype=np.float64),
                np.asarray(data["flown_steps"], dtype=np.float64),
                np.asarray(data["interventions"], dtype=np.float64),
            )
        return cls(
            success=np.asarray(data["success"], dtype=bool),
            cost=np.asarray(data["cost"], dtype=np.float64),
            returns=np.asarray(data["return"], dtype=np.float64) if "return" in data else None,
            out_of_area=np.asarray(data["out_of_area"], dtype=bool) if "out_of_area" in data else None,
            monitor=monitor,
        )


@dataclass(frozen=True)
class TeamEvaluation:
    """What the report reads of one cached evaluation (one team, one EvalSpec)."""

    success_rate: float
    mean_cost: float
    """Hazard cost per UAV per mission."""
    episodes: int
    cost_limit: float
    """The scenario's C."""
    backup_time_fraction: float | None
    """With the monitor: the share of flight time under the backup."""
    per_episode: PerEpisode
    success_interval95: tuple[float, float] | None
    """95% Wilson score interval (None in a cache written before evaluations had intervals)."""
    mean_cost_interval95: tuple[float, float] | None
    """95% bootstrap interval over missions (None likewise)."""
    tasks_finished: dict[str, int] | None = None
    """Per role, the missions in which that role finished its task (None in a cache without per-role figures)."""

    @classmethod
    def from_record(cls, data: dict[str, Any]) -> TeamEvaluation:
        """From a cache file's contents (:func:`evaluate`): its evaluation record and ``per_episode``."""
        record = EvaluationRecord.from_json(data)
        if record.success_rate is None or record.mean_cost is None or not isinstance(record.run, BatchedRun):
            raise RecordError("not a batched evaluation: no success rate, mean cost, or what flew it")
        tasks = None
        if record.roles:  # a rate over the evaluation's missions: back to a count
            tasks = {
                role: round((figures.task_success_rate or 0.0) * record.episodes)
                for role, figures in record.roles.items()
            }
        monitor = record.monitor
        return cls(
            success_rate=record.success_rate,
            mean_cost=record.mean_cost,
            episodes=record.episodes,
            cost_limit=record.run.cost_limit,
            backup_time_fraction=monitor.backup_time_fraction if monitor is not None else None,
            per_episode=PerEpisode.from_record(data["per_episode"]),
            success_interval95=record.success_interval95,
            mean_cost_interval95=record.mean_cost_interval95,
            tasks_finished=tasks,
        )


def team_digest(team: Path) -> str:
    """A hash of what the three role checkpoints fly with (actor weights, observation mode, decision
    interval): a cached evaluation belongs to exactly these pilots, also after ``--compact``."""
    # A cached evaluation is never of a changed file.
    warn_once(check_models(team, [f"{role.value}.pt" for role in ROLES]))
    h = hashlib.sha256()
    for role in ROLES:
        path = team / f"{role.value}.pt"
        from tssac_core.deploy.policy import checkpoint_info, read_checkpoint  # torch, when a team is read

        data = read_checkpoint(path)
        info = checkpoint_info(data, path)
        h.update(f"{info.role.value} {info.observation_mode.value} {info.action_repeat} {info.hidden_sizes}".encode())
        for name, tensor in sorted(data["actor"].items()):
            h.update(name.encode())
            h.update(tensor.detach().cpu().numpy().tobytes())
    return h.hexdigest()[:16]


class CacheKey(TypedDict):
    """What a cached evaluation was made from (:func:`cache_key`)."""

    team: str
    """The team's digest (:func:`team_digest`), or the guidance controller's name."""
    scenario_digest: str
    seed: int
    episodes: int
    layouts: NotRequired[str]
    shield: NotRequired[dict[str, float | Sequence[float]]]
    """The monitor's settings (ShieldConfig's fields)."""


def cache_key(team: Path | None, spec: EvalSpec) -> CacheKey:
    """What a cached evaluation must have been made from to stand for ``team`` flying ``spec``: the pilots, the task,
    the seed, the number of layouts, their rule (a key without ``layouts`` is LayoutRule.IN_TURN, the only rule when
    the 50-layout caches were written) and the monitor's settings."""
    key: CacheKey = {
        "team": team_digest(team) if team is not None else GUIDANCE,
        "scenario_digest": load(spec.scenario).digest(),
        "seed": spec.seed,
        "episodes": spec.episodes,
    }
    if spec.layouts is not LayoutRule.IN_TURN:
        key["layouts"] = spec.layouts.value
    if spec.monitor:
        key["shield"] = dataclasses.asdict(ShieldConfig())
    return json.loads(json.dumps(key))  # as a cache file holds it (tuples become lists)


def cached(team: Path | None, spec: EvalSpec, cache: Path) -> TeamEvaluation | None:
    """The evaluation in ``cache`` if it was made from ``team`` flying ``spec`` (:func:`cache_key`), else None."""
    if not cache.is_file():
        return None
    try:
        data = json.loads(cache.read_text())
    except ValueError:
        return None
    if data.get("cache_key") != cache_key(team, spec) or "per_episode" not in data:
        return None
    try:
        return TeamEvaluation.from_record(data)
    except (RecordError, KeyError, TypeError, ValueError):  # a damaged cache is flown again, as a stale one is
        return None


def evaluate(team: Path | None, spec: EvalSpec, cache: Path) -> TeamEvaluation:
    """``team`` (None: the guidance controller) flying ``spec``, from ``cache`` if it still fits, else flown and
    cached.

    The cache file has the keys of ``tssac_core.evaluate --json`` (with ``--shield``: its ``shield`` figures) plus
    ``per_episode``: ``success`` (M,), ``cost`` (M, 3) per role, and ``return`` (M, 3) for the box plots or, for
    the tails, ``out_of_area`` (M, 3) and with the monitor its counts per UAV-mission (``backup_steps``,
    ``flown_steps``, ``interventions``).
    """
    hit = cached(team, spec, cache)
    if hit is not None:
        return hit
    scenario = load(spec.scenario)
    pilots: list[PilotSpec] = team_pilots(team) if team is not None else [GUIDANCE] * len(ROLES)
    layouts = layouts_in_turn(scenario, spec.episodes, spec.seed) if spec.layouts is LayoutRule.IN_TURN else None
    results = fly_missions(
        scenario, pilots, spec.episodes, spec.seed, layouts=layouts, shield=ShieldConfig() if spec.monitor else None
    )
    record = dataclasses.replace(
        results.record(scenario.cost_limit),
        run=BatchedRun(
            controller=str(team) if team is not None else GUIDANCE,
            scenario=str(spec.scenario),
            seed=spec.seed,
            cost_limit=scenario.cost_limit,
        ),
    )
    per_episode: PerEpisodeJson = {"success": results.success.tolist(), "cost": results.cost.tolist()}
    if spec.label.is_tail:
        per_episode["out_of_area"] = results.out_of_area.tolist()
    else:
        per_episode["return"] = results.returns.tolist()
    if results.monitor is not None:
        record = record.with_monitor_config(dataclasses.asdict(ShieldConfig()))
        per_episode["backup_steps"] = results.monitor.backup_steps.tolist()
        per_episode["flown_steps"] = results.monitor.flown_steps.tolist()
        per_episode["interventions"] = results.monitor.interventions.tolist()
    data = {**record.to_json(), "cache_key": cache_key(team, spec), "per_episode": per_episode}
    write_json(cache, data)
    return TeamEvaluation.from_record(data)


def team_pilots(team: Path) -> list[PilotSpec]:
    """The three role policies of a models directory (torch is imported here, when a team is first flown)."""
    from tssac_core.deploy.policy import load_team

    return list(load_team(team))


def fly_one(team: Path, spec: EvalSpec) -> MissionResults:
    """The first evaluation layout, flown by ``team`` with its trajectories recorded (figure 9)."""
    scenario = load(spec.scenario)
    return fly_missions(
        scenario, team_pilots(team), 1, spec.seed, record=True, layouts=layouts_in_turn(scenario, 1, spec.seed)
    )


Evaluations = dict[tuple[str, EvalLabel], TeamEvaluation]
"""(job name or GUIDANCE, evaluation) -> what it flew."""


def evaluate_all(
    grid: Grid, finished: list[Job], results: Path, report: Callable[[str], None], cached_tail: bool = False
) -> Evaluations:
    """Every finished team and the guidance controller on every EvalSpec (cached). The tail evaluations are flown
    seed-major (every algorithm's first seed before any second), each cached as soon as it is flown; with
    ``cached_tail`` none is flown, and those not cached are left out (the table says which seeds it pools)."""
    out: Evaluations = {}
    order = sorted(finished, key=lambda j: (j.seed, [e.name for e in grid.algos].index(j.entry.name)))
    for spec in eval_specs(grid):
        tail = spec.label.is_tail
        report(
            f"evaluating on {spec.scenario.name}: {spec.episodes} layouts, seed {spec.seed}"
            + f" ({spec.layouts.value})"
            + (", with the monitor" if spec.monitor else "")
        )
        for team, name, cache in [
            (None, GUIDANCE, results / "guidance" / spec.cache_name()),
            *[(j.out, j.name, j.out / spec.cache_name()) for j in (order if tail else finished)],
        ]:
            if tail and cached_tail:
                hit = cached(team, spec, cache)
                if hit is None:
                    report(f"  {name}: not cached, left out (--cached-tail)")
                    continue
                out[(name, spec.label)] = hit
                continue
            out[(name, spec.label)] = evaluate(team, spec, cache)
            if tail:
                report(f"  {name}: {tail_line(out[(name, spec.label)])}")
    return out


def tail_line(evaluation: TeamEvaluation) -> str:
    """One evaluation's success and cost with their intervals (and the time under the backup), for the progress log."""
    assert evaluation.success_interval95 is not None and evaluation.mean_cost_interval95 is not None, "flown now"
    lo, hi = evaluation.success_interval95
    clo, chi = evaluation.mean_cost_interval95
    line = (
        f"success {100 * evaluation.success_rate:.1f}% ({100 * lo:.1f}-{100 * hi:.1f}), "
        f"cost {evaluation.mean_cost:.2f} ({clo:.2f}-{chi:.2f})"
    )
    if evaluation.backup_time_fraction is not None:
        line += f", {100 * evaluation.backup_time_fraction:.1f}% of flight time under the backup"
    return line
