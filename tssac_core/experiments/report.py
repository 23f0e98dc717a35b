"""Evaluate a grid's finished teams on the same layouts and write Table 4 (``table4.md``) and ``experiments.json``.

Every finished team, and the guidance controller as a reference row, flies the evaluation scenario's
layouts drawn from the grid's evaluation seed (the same layouts for every team), and the generalisation
scenario's if the grid names one. With ``evaluation.tail_episodes`` (issue 23) every team also flies that many
more layouts (e.g. 500, their own seed), reported pooled over its seeds: success with its 95% Wilson interval,
the mean hazard cost per UAV with its 95% bootstrap interval over missions, the within-C fraction and the tail
(:mod:`tssac_core.stats`); with ``tail_monitor`` it flies them a second time through the runtime-assurance
monitor (issue 24, ``evaluate --shield``): success, cost and the fraction of flight time under the backup.

Each evaluation is cached as JSON next to the team (``<run>/eval_random.json``, ``eval_generalization.json``,
``eval_tail.json``, ``eval_tail_monitor.json``; the guidance controller's under ``<results>/guidance/``) with the
per-episode figures the box plots and the pooled intervals need; a cache is reused only if it was made from the
same checkpoints, scenario, seed, number of episodes and layout rule (and monitor settings), so an interrupted
report flies only what is missing when it runs again.

Figures per algorithm are mean ± sample standard deviation over its finished seeds. The transfer speed-up
compares, for the detect and strike roles, the learner decisions (``env_steps`` in metrics.csv) until the
first epoch whose task success reaches 90%, TSSAC against SAC-Lagrangian, and the task success averaged
over the role's epochs (which also compares runs that never reach 90%).
"""

from __future__ import annotations

import csv
import dataclasses
import enum
import hashlib
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.cli import write_json
from tssac_core.deploy.manifest import check_models, warn_once
from tssac_core.experiments.grid import Grid, Job
from tssac_core.sim.missions import MissionResults, fly_missions
from tssac_core.sim.scenario import ROLES, Layout, Scenario, load, sample_layout
from tssac_core.sim.team import GUIDANCE, Pilot
from tssac_core.stats import bootstrap_mean_interval, cvar, wilson_interval, within_fraction
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

TRANSFER_THRESHOLD = 0.9
TRANSFER_ROLES = ("detect", "strike")
GUIDANCE_NAME = "guidance controller"
TAIL_LABELS = ("tail", "tail_monitor")


class LayoutRule(enum.Enum):
    """How an evaluation's M layouts come from its seed S."""

    IN_TURN = "drawn in turn from one generator seeded S"
    """Table 4's 50 layouts and figure 11's, as every table of this grid has flown them (the rule of
    ``tssac_core.evaluate`` before each mission had its own seed): kept, so that the paper's protocol flies the
    same layouts as before and its cached evaluations stand."""
    PER_MISSION = "mission k: layout seed S + k"
    """The tail's layouts: ``tssac_core.sim.missions.mission_layout``, as ``tssac_core.evaluate`` and
    ``mavlink_bridge.fly`` draw them now, so that ``evaluate --seed S --mission k`` flies any one of them again."""


def layouts_in_turn(scenario: Scenario, episodes: int, seed: int) -> list[Layout]:
    """``episodes`` layouts drawn one after another from one generator seeded ``seed`` (LayoutRule.IN_TURN)."""
    rng = np.random.default_rng(seed)
    return [sample_layout(scenario, rng) for _ in range(episodes)]


@dataclass(frozen=True)
class EvalSpec:
    """One evaluation every team flies."""

    label: str
    """``random`` (Table 4, figure 10), ``generalization`` (figure 11), ``tail`` (the many-layout columns) or
    ``tail_monitor`` (the same layouts with the monitor); names the cache file."""
    scenario: Path
    episodes: int
    seed: int
    monitor: bool = False
    """Fly every UAV through the runtime-assurance monitor (``evaluate --shield``, its default margins)."""
    layouts: LayoutRule = LayoutRule.IN_TURN

    def cache_name(self) -> str:
        return f"eval_{self.label}.json"


def eval_specs(grid: Grid) -> list[EvalSpec]:
    ev = grid.evaluation
    specs = [EvalSpec("random", ev.scenario, ev.episodes, ev.seed)]
    if ev.generalization_scenario is not None:
        specs.append(EvalSpec("generalization", ev.generalization_scenario, ev.episodes, ev.seed))
    if ev.tail_episodes is not None:
        specs.append(EvalSpec("tail", ev.scenario, ev.tail_episodes, ev.tail_seed, layouts=LayoutRule.PER_MISSION))
        if ev.tail_monitor:
            specs.append(
                EvalSpec(
                    "tail_monitor",
                    ev.scenario,
                    ev.tail_episodes,
                    ev.tail_seed,
                    monitor=True,
                    layouts=LayoutRule.PER_MISSION,
                )
            )
    return specs


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


def cache_key(team: Path | None, spec: EvalSpec) -> dict[str, Any]:
    """What a cached evaluation must have been made from to stand for ``team`` flying ``spec``: the pilots, the task,
    the seed, the number of layouts, their rule (a key without ``layouts`` is LayoutRule.IN_TURN, the only rule when
    the 50-layout caches were written) and the monitor's settings."""
    key: dict[str, Any] = {
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


def cached(team: Path | None, spec: EvalSpec, cache: Path) -> dict[str, Any] | None:
    """The evaluation in ``cache`` if it was made from ``team`` flying ``spec`` (:func:`cache_key`), else None."""
    if not cache.is_file():
        return None
    try:
        data = json.loads(cache.read_text())
    except ValueError:
        return None
    return dict(data) if data.get("cache_key") == cache_key(team, spec) and "per_episode" in data else None


def evaluate(team: Path | None, spec: EvalSpec, cache: Path) -> dict[str, Any]:
    """The summary of ``team`` (None: the guidance controller) flying ``spec``, from ``cache`` if it still fits.

    The summary has the keys of ``tssac_core.evaluate --json`` (with ``--shield``: its ``shield`` figures) plus
    ``per_episode``: ``success`` (M,), ``cost`` (M, 3) per role, and ``return`` (M, 3) for the box plots or, for
    the tail, ``out_of_area`` (M, 3) and with the monitor its counts per UAV-mission (``backup_steps``,
    ``flown_steps``, ``interventions``).
    """
    hit = cached(team, spec, cache)
    if hit is not None:
        return hit
    scenario = load(spec.scenario)
    pilots: list[Pilot] = team_pilots(team) if team is not None else [GUIDANCE] * len(ROLES)
    layouts = layouts_in_turn(scenario, spec.episodes, spec.seed) if spec.layouts is LayoutRule.IN_TURN else None
    results = fly_missions(
        scenario, pilots, spec.episodes, spec.seed, layouts=layouts, shield=ShieldConfig() if spec.monitor else None
    )
    summary = results.summary(scenario.cost_limit)
    per_episode: dict[str, Any] = {"success": results.success.tolist(), "cost": results.cost.tolist()}
    if spec.label in TAIL_LABELS:
        per_episode["out_of_area"] = results.out_of_area.tolist()
    else:
        per_episode["return"] = results.returns.tolist()
    if results.monitor is not None:
        summary["shield"]["config"] = dataclasses.asdict(ShieldConfig())
        per_episode.update(
            {
                "backup_steps": results.monitor.backup_steps.tolist(),
                "flown_steps": results.monitor.flown_steps.tolist(),
                "interventions": results.monitor.interventions.tolist(),
            }
        )
    summary.update(
        {
            "controller": str(team) if team is not None else GUIDANCE,
            "scenario": str(spec.scenario),
            "seed": spec.seed,
            "cost_limit": scenario.cost_limit,
            "cache_key": cache_key(team, spec),
            "per_episode": per_episode,
        }
    )
    write_json(cache, summary)
    return summary


def team_pilots(team: Path) -> list[Pilot]:
    """The three role policies of a models directory (torch is imported here, when a team is first flown)."""
    from tssac_core.deploy.policy import load_team

    return list(load_team(team))


def fly_one(team: Path, spec: EvalSpec) -> MissionResults:
    """The first evaluation layout, flown by ``team`` with its trajectories recorded (figure 9)."""
    scenario = load(spec.scenario)
    return fly_missions(
        scenario, team_pilots(team), 1, spec.seed, record=True, layouts=layouts_in_turn(scenario, 1, spec.seed)
    )


Evaluations = dict[tuple[str, str], dict[str, Any]]
"""(job name or GUIDANCE, eval label) -> evaluation summary."""


def within_limit(evaluation: dict[str, Any]) -> float:
    """The share of UAV-missions (every role of every mission) whose hazard cost is within the scenario's
    limit: how often the constraint held, beside the mean that one long stay inside a radar can dominate."""
    return float(np.mean(np.asarray(evaluation["per_episode"]["cost"]) <= evaluation["cost_limit"]))


def pooled_cost(evaluations: list[dict[str, Any]]) -> dict[str, Any]:
    """The mean hazard cost per UAV per mission over every seed's missions pooled, with a 95% percentile
    bootstrap interval over missions (:func:`tssac_core.stats.bootstrap_mean_interval`: a mission's three UAVs
    resampled together, fixed resampling seed), the UAV-missions over the limit and the largest single costs.

    A mean cost near the limit C = 3 is made of rare long stays inside a radar (one of 500-800 steps is
    a whole evaluation's mean of 3-5), so a 50-layout mean alone cannot say on which side of C a policy is;
    the interval says how far the figure can be trusted."""
    if not evaluations:
        return {"uav_missions": 0, "mean": None, "ci95": None, "over_limit": 0, "largest": []}
    costs = np.concatenate([np.asarray(e["per_episode"]["cost"], dtype=np.float64) for e in evaluations])  # (M, 3)
    mean = bootstrap_mean_interval(costs)
    limit = evaluations[0]["cost_limit"]
    return {
        "uav_missions": int(costs.size),
        "mean": float(costs.mean()),
        "ci95": [mean.low, mean.high],
        "over_limit": int((costs > limit).sum()),
        "largest": sorted(costs.ravel().tolist(), reverse=True)[:3],
    }


def pooled_tail(evaluations: list[dict[str, Any]]) -> dict[str, Any]:
    """The tail evaluations of an algorithm's seeds pooled into one sample of missions (:mod:`tssac_core.stats`):
    success k of n with its 95% Wilson interval; the mean hazard cost per UAV with its 95% bootstrap interval over
    missions (a mission's three UAVs resampled together); the within-C fraction of the UAV-missions, how many are
    over C, their CVaR at 95% and the largest costs; the UAVs that left the area; and, for evaluations flown with
    the monitor, the fraction of flight time under the backup and the interventions per UAV-mission. None of these
    without evaluations (``missions`` 0)."""
    if not evaluations:
        return {"missions": 0, "seeds": 0}
    per = [e["per_episode"] for e in evaluations]
    success = np.concatenate([np.asarray(p["success"], dtype=bool) for p in per])
    cost = np.concatenate([np.asarray(p["cost"], dtype=np.float64) for p in per])  # (M, 3)
    limit = evaluations[0]["cost_limit"]
    rate, mean = wilson_interval(int(success.sum()), int(success.size)), bootstrap_mean_interval(cost)
    out: dict[str, Any] = {
        "missions": int(success.size),
        "seeds": len(evaluations),
        "success_rate": rate.value,
        "success_interval95": [rate.low, rate.high],
        "mean_cost": mean.value,
        "mean_cost_interval95": [mean.low, mean.high],
        "within_cost_limit": within_fraction(cost, limit),
        "over_limit": int((cost > limit).sum()),
        "cvar95_cost": cvar(cost),
        "largest": sorted(cost.ravel().tolist(), reverse=True)[:3],
        "left_area": int(sum(np.asarray(p["out_of_area"], dtype=bool).sum() for p in per)),
    }
    if all("backup_steps" in p for p in per):
        backup = sum(float(np.sum(p["backup_steps"])) for p in per)
        flown = sum(float(np.sum(p["flown_steps"])) for p in per)
        out["backup_time_fraction"] = backup / max(1.0, flown)
        out["interventions_per_uav_mission"] = float(
            np.concatenate([np.asarray(p["interventions"], dtype=np.float64) for p in per]).mean()
        )
    return out


def evaluate_all(
    grid: Grid, finished: list[Job], results: Path, report: Callable[[str], None], cached_tail: bool = False
) -> Evaluations:
    """Every finished team and the guidance controller on every EvalSpec (cached). The tail evaluations are flown
    seed-major (every algorithm's first seed before any second), each cached as soon as it is flown; with
    ``cached_tail`` none is flown, and those not cached are left out (the table says which seeds it pools)."""
    out: Evaluations = {}
    order = sorted(finished, key=lambda j: (j.seed, [e.name for e in grid.algos].index(j.entry.name)))
    for spec in eval_specs(grid):
        tail = spec.label in TAIL_LABELS
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


def tail_line(evaluation: dict[str, Any]) -> str:
    """One evaluation's success and cost with their intervals (and the time under the backup), for the progress log."""
    lo, hi = evaluation["success_interval95"]
    clo, chi = evaluation["mean_cost_interval95"]
    line = (
        f"success {100 * evaluation['success_rate']:.1f}% ({100 * lo:.1f}-{100 * hi:.1f}), "
        f"cost {evaluation['mean_cost']:.2f} ({clo:.2f}-{chi:.2f})"
    )
    if "shield" in evaluation:
        line += f", {100 * evaluation['shield']['backup_time_fraction']:.1f}% of flight time under the backup"
    return line


# ------------------------------------------------------------------------------------ figures


def over_seeds(per_seed: dict[int, float]) -> dict[str, Any]:
    """Mean and sample standard deviation over seeds (std None with fewer than two)."""
    values = list(per_seed.values())
    return {
        "mean": float(np.mean(values)) if values else None,
        "std": float(np.std(values, ddof=1)) if len(values) > 1 else None,
        "per_seed": {str(s): v for s, v in per_seed.items()},
    }


PAPER_EPOCHS = 50
"""Table 3: epochs per role."""


def read_metrics(run: Path) -> list[dict[str, str]]:
    path = run / "metrics.csv"
    if not path.is_file():
        return []
    with path.open() as fh:
        return list(csv.DictReader(fh))


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return math.nan


def steps_to_threshold(
    rows: list[dict[str, str]], role: str, threshold: float = TRANSFER_THRESHOLD
) -> tuple[int | None, int]:
    """(env_steps at the end of the first epoch with task_success >= threshold, or None; the role's total env_steps)."""
    sel = sorted((r for r in rows if r["role"] == role), key=lambda r: int(r["epoch"]))
    total = int(_number(sel[-1]["env_steps"])) if sel else 0
    for r in sel:
        if _number(r["task_success"]) >= threshold:
            return int(_number(r["env_steps"])), total
    return None, total


def mean_task_success(rows: list[dict[str, str]], role: str) -> float:
    """The role's training task success averaged over its epochs: how early it learned, in one number
    that also compares runs that never reach the threshold (the area under its learning curve)."""
    values = [v for r in rows if r["role"] == role and math.isfinite(v := _number(r["task_success"]))]
    return float(np.mean(values)) if values else math.nan


def steps_figures(jobs: list[Job], role: str, threshold: float) -> dict[str, Any]:
    """Decisions until ``role`` first reached ``threshold`` task success in each run, and their mean over seeds.

    A seed that never reached it counts with its role's total decisions, a lower bound of what it would have
    needed; the mean is then marked as a lower bound.
    """
    per_seed: dict[str, int | None] = {}
    counted: list[int] = []
    mean_task: dict[int, float] = {}
    for job in jobs:
        rows = read_metrics(job.out)
        reached, total = steps_to_threshold(rows, role, threshold)
        per_seed[str(job.seed)] = reached
        counted.append(reached if reached is not None else total)
        mean_task[job.seed] = mean_task_success(rows, role)
    return {
        "entry": jobs[0].entry.name if jobs else None,
        "per_seed": per_seed,
        "counted": {str(job.seed): c for job, c in zip(jobs, counted)},
        "seeds": len(jobs),
        "reached": sum(v is not None for v in per_seed.values()),
        "mean_steps": float(np.mean(counted)) if counted else None,
        "mean_is_lower_bound": any(v is None for v in per_seed.values()),
        "mean_task_success": over_seeds(mean_task),
    }


def speedup(slow: dict[str, Any], fast: dict[str, Any]) -> dict[str, Any]:
    """Mean decisions without transfer over those with it; a lower bound when only the slow side's mean is one
    (if the fast side's mean is a lower bound, the ratio bounds nothing and is left out)."""
    ratio = None
    if fast["mean_steps"] and slow["mean_steps"] is not None and not fast["mean_is_lower_bound"]:
        ratio = slow["mean_steps"] / fast["mean_steps"]
    return {"speedup": ratio, "speedup_is_lower_bound": ratio is not None and slow["mean_is_lower_bound"]}


def transfer_speedup(grid: Grid, finished: list[Job]) -> dict[str, Any]:
    """Decisions until >= 90% task success in the grid's own curricula, TSSAC vs SAC-Lagrangian, per role
    (mean over finished seeds; :func:`steps_figures`, :func:`speedup`)."""
    out: dict[str, Any] = {"threshold": TRANSFER_THRESHOLD}
    for role in TRANSFER_ROLES:
        per_algo: dict[str, Any] = {}
        for algo in ("tssac", "sac_lag"):
            entry = next((e for e in grid.algos if e.algo == algo), None)
            per_algo[algo] = steps_figures(
                [j for j in finished if entry is not None and j.entry == entry], role, TRANSFER_THRESHOLD
            )
            per_algo[algo]["entry"] = entry.name if entry is not None else None
        out[role] = {**per_algo, **speedup(per_algo["sac_lag"], per_algo["tssac"])}
    return out


def transfer_experiment(grid: Grid, runs: list[Job]) -> dict[str, Any] | None:
    """The transfer experiment's figures (``grid.transfer``) from its finished runs: per role, the decisions
    to the level with transfer and without, and the speed-up. None if the grid has no such experiment."""
    t = grid.transfer
    if t is None:
        return None
    out: dict[str, Any] = {
        "threshold": t.task_success,
        "teammates": shown(t.teammates),
        "epochs": t.epochs,
        "steps_per_epoch": grid.train.steps_per_epoch,
        "roles": list(t.roles),
    }
    for role in t.roles:
        sides = {
            side: steps_figures([j for j in runs if j.role == role and j.entry == entry], role, t.task_success)
            for side, entry in (("with", t.with_transfer), ("without", t.without_transfer))
        }
        out[role] = {**sides, **speedup(sides["without"], sides["with"])}
    return out


def summarise(
    grid: Grid,
    jobs: list[Job],
    finished: list[Job],
    evaluations: Evaluations,
    results: Path,
    transfer_runs: Sequence[Job] = (),
) -> dict[str, Any]:
    """Everything ``experiments.json`` holds."""
    labels = [spec.label for spec in eval_specs(grid) if spec.label not in TAIL_LABELS]
    tails = [spec.label for spec in eval_specs(grid) if spec.label in TAIL_LABELS]
    algorithms = []
    for entry in grid.algos:
        mine = [j for j in finished if j.entry == entry]
        row: dict[str, Any] = {
            "name": entry.name,
            "algo": entry.algo,
            "penalty": entry.penalty,
            "seeds": [j.seed for j in mine],
        }
        for label in tails:
            flown = [j for j in mine if (j.name, label) in evaluations]
            row[label] = {
                **pooled_tail([evaluations[(j.name, label)] for j in flown]),
                "flown_seeds": [j.seed for j in flown],
                "per_seed": {
                    str(j.seed): {k: evaluations[(j.name, label)][k] for k in ("success_rate", "mean_cost")}
                    for j in flown
                },
            }
        for label in labels:
            row[label] = {
                key: over_seeds({j.seed: evaluations[(j.name, label)][key] for j in mine})
                for key in ("success_rate", "mean_cost")
            }
            row[label]["within_cost_limit"] = over_seeds(
                {j.seed: within_limit(evaluations[(j.name, label)]) for j in mine}
            )
            row[label]["pooled_cost"] = pooled_cost([evaluations[(j.name, label)] for j in mine])
        walls = {j.seed: w for j in mine if (w := training_wall_s(j.out)) is not None}
        row["training_wall_s"] = over_seeds(walls)
        paper = PAPER_TABLE4.get(entry.algo) if entry.algo != "sac_penalty" else None
        row["paper"] = {"success_rate": paper[0], "mean_cost": paper[1]} if paper else None
        algorithms.append(row)
    guidance: dict[str, Any] = {
        label: {
            **{key: evaluations[(GUIDANCE, label)][key] for key in ("success_rate", "mean_cost", "episodes")},
            "within_cost_limit": within_limit(evaluations[(GUIDANCE, label)]),
        }
        for label in labels
    }
    guidance.update(
        {
            label: pooled_tail([evaluations[(GUIDANCE, label)]] if (GUIDANCE, label) in evaluations else [])
            for label in tails
        }
    )
    ev = grid.evaluation
    return {
        "grid": shown(grid.source),
        "results": shown(results),
        "evaluation": {
            "scenario": shown(ev.scenario),
            "episodes": ev.episodes,
            "seed": ev.seed,
            "generalization_scenario": shown(ev.generalization_scenario) if ev.generalization_scenario else None,
            "tail_episodes": ev.tail_episodes,
            "tail_seed": ev.tail_seed if ev.tail_episodes else None,
            "tail_monitor": ev.tail_monitor if ev.tail_episodes else None,
            "layouts": LayoutRule.IN_TURN.value,
            "tail_layouts": LayoutRule.PER_MISSION.value if ev.tail_episodes else None,
        },
        "training": {
            "epochs_per_role": grid.train.epochs,
            "steps_per_epoch": grid.train.steps_per_epoch,
            "action_repeat": grid.train.action_repeat,
            "paper_epochs_per_role": PAPER_EPOCHS,
        },
        "cost_limit": load(ev.scenario).cost_limit,
        "algorithms": algorithms,
        "guidance": guidance,
        "transfer_speedup": transfer_speedup(grid, finished),
        "transfer_experiment": transfer_experiment(grid, list(transfer_runs)),
        "left_out": [j.name for j in jobs if j not in finished],
    }


def shown(path: Path) -> str:
    """A path as a user of this directory would write it: relative to the working directory if inside it."""
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


# -------------------------------------------------------------------------------------- table


def _rate(stats: dict[str, Any]) -> str:
    if stats["mean"] is None:
        return "—"
    return f"{100 * stats['mean']:.1f}%" + (f" ± {100 * stats['std']:.1f}" if stats["std"] is not None else "")


def _cost(stats: dict[str, Any]) -> str:
    if stats["mean"] is None:
        return "—"
    return f"{stats['mean']:.2f}" + (f" ± {stats['std']:.2f}" if stats["std"] is not None else "")


def _steps(figures: dict[str, Any]) -> str:
    if figures["mean_steps"] is None:
        return "—"
    bound = ">= " if figures["mean_is_lower_bound"] else ""
    return f"{bound}{figures['mean_steps']:,.0f} (reached in {figures['reached']} of {figures['seeds']} seeds)"


def _minutes(stats: dict[str, Any]) -> str:
    if stats["mean"] is None:
        return "—"
    return f"{stats['mean'] / 60:.0f} min" + (f" ± {stats['std'] / 60:.0f}" if stats["std"] is not None else "")


def _budget(training: dict[str, Any]) -> str:
    """The training budget beside the table: every algorithm alike, and how it compares with the paper's."""
    epochs, paper = training["epochs_per_role"], training["paper_epochs_per_role"]
    text = (
        f"Training budget, the same for every algorithm: {epochs} epochs x {training['steps_per_epoch']:,} learner "
        f"decisions "
        f"per role (one decision per {training['action_repeat']} world steps of 0.1 s)."
    )
    if epochs < paper:
        text += (
            f" **Shrunk from the paper's {paper} epochs** to fit the grid on this machine: "
            f"{epochs / paper:.0%} of its training."
        )
    return text


def _tail_rate(t: dict[str, Any], of_seeds: int | None = None) -> str:
    """Pooled success with its 95% Wilson interval; with ``of_seeds``, how many of the finished seeds it pools (if
    not all)."""
    if not t["missions"]:
        return "—"
    lo, hi = t["success_interval95"]
    text = f"{100 * t['success_rate']:.1f}% ({100 * lo:.1f}-{100 * hi:.1f})"
    return text + (f" [{t['seeds']} of {of_seeds} seeds]" if of_seeds is not None and t["seeds"] < of_seeds else "")


def _tail_cost(t: dict[str, Any]) -> str:
    if not t["missions"]:
        return "—"
    lo, hi = t["mean_cost_interval95"]
    return f"{t['mean_cost']:.2f} ({lo:.2f}-{hi:.2f})"


def _tail_share(t: dict[str, Any], key: str) -> str:
    return f"{100 * t[key]:.1f}%" if t["missions"] and key in t else "—"


def _largest(values: list[float]) -> str:
    return ", ".join(f"{v:,.0f}" for v in values if v > 0) or "—"


def tail_columns(summary: dict[str, Any]) -> tuple[list[str], dict[str, list[str]]]:
    """The main table's extra columns for the tail evaluation (and the monitor): headers, and cells per row name."""
    ev = summary["evaluation"]
    if not ev.get("tail_episodes"):
        return [], {}
    n = ev["tail_episodes"]
    headers = [
        f"{n} layouts: success rate (95% interval)",
        f"{n} layouts: average cost (95% interval)",
        f"{n} layouts: within C",
    ]
    if ev["tail_monitor"]:
        headers += [
            "with monitor: success rate (95% interval)",
            "with monitor: average cost (95% interval)",
            "with monitor: time under backup",
        ]
    rows = {}
    for name, tails, seeds in [
        *[(a["name"], a, len(a["seeds"])) for a in summary["algorithms"]],
        (GUIDANCE_NAME, summary["guidance"], None),
    ]:
        cells = [
            _tail_rate(tails["tail"], seeds),
            _tail_cost(tails["tail"]),
            _tail_share(tails["tail"], "within_cost_limit"),
        ]
        if ev["tail_monitor"]:
            on = tails["tail_monitor"]
            cells += [_tail_rate(on, seeds), _tail_cost(on), _tail_share(on, "backup_time_fraction")]
        rows[name] = cells
    return headers, rows


def tail_markdown(summary: dict[str, Any]) -> list[str]:
    """The section on the tail evaluation: what its columns are, how to fly one again, and its tail figures."""
    ev = summary["evaluation"]
    n, seed, monitor = ev["tail_episodes"], ev["tail_seed"], ev["tail_monitor"]
    lines = [
        "",
        f"## {n} layouts per team, with intervals{', and with the runtime-assurance monitor' if monitor else ''}",
        "",
        f'The columns "{n} layouts": every team flies {n} more layouts of `{ev["scenario"]}`, mission k on the '
        f"layout of seed {seed} + k, as `tssac_core.evaluate` draws them (layout seeds {seed}-{seed + n - 1}: never "
        f"used in training, in epoch selection or in the {ev['episodes']} layouts above), the same layouts for every "
        f"team. An algorithm's seeds are pooled into one sample ({n} missions per seed): success with its 95% Wilson "
        "interval, the mean hazard cost per UAV with its 95% bootstrap interval over missions (a mission's three UAVs "
        "resampled together; `tssac_core.stats`), and the share of UAV-missions within C. Where a row pools fewer "
        "seeds than it has, the success cell says so.",
    ]
    if monitor:
        lines += [
            "",
            'The columns "with monitor": the same layouts flown again through the runtime-assurance monitor '
            "(`python -m tssac_core.evaluate --shield`, docs/runtime_assurance.md), which hands a UAV to its backup "
            "manoeuvre when the path it predicts would enter a radar's disk or leave the area: success, cost, and the "
            "share of flight time under the backup.",
        ]
    lines += [
        "",
        "Each run's evaluations are cached beside it (`runs/<run>/eval_tail.json`"
        + (", `eval_tail_monitor.json`" if monitor else "")
        + "; "
        "the guidance controller's in `guidance/`), with the worst missions' layout seeds; one run again: `python -m "
        f"tssac_core.evaluate --models runs/<run> --scenario {ev['scenario']} --episodes {n} --seed {seed}"
        f"{' [--shield]' if monitor else ''}`, one mission of it `--seed {seed} --mission K`.",
        "",
        "| algorithm | seeds flown | per seed: success, cost | UAV-missions over C | CVaR95 | largest | "
        "UAVs that left the area |"
        + (
            " with monitor: over C | with monitor: UAVs that left the area | "
            "with monitor: interventions per UAV-mission |"
            if monitor
            else ""
        ),
        "| --- | --- | --- | --- | --- | --- | --- |" + (" --- | --- | --- |" if monitor else ""),
    ]
    for a in [*summary["algorithms"], {"name": GUIDANCE_NAME, "guidance": True, **summary["guidance"]}]:
        t = a["tail"]
        if not t["missions"]:
            cells = [", ".join(map(str, t.get("flown_seeds", []))) or "none", "—", "—", "—", "—", "—"]
        else:
            per_seed = "; ".join(
                f"{s}: {100 * f['success_rate']:.1f}%, {f['mean_cost']:.2f}" for s, f in t.get("per_seed", {}).items()
            )
            cells = [
                "—" if a.get("guidance") else ", ".join(map(str, t["flown_seeds"])),
                per_seed or "—",
                f"{t['over_limit']} of {3 * t['missions']}",
                f"{t['cvar95_cost']:.1f}",
                _largest(t["largest"]),
                str(t["left_area"]),
            ]
        if monitor:
            on = a["tail_monitor"]
            cells += (
                [
                    f"{on['over_limit']} of {3 * on['missions']}",
                    str(on["left_area"]),
                    f"{on['interventions_per_uav_mission']:.2f}",
                ]
                if on["missions"]
                else ["—", "—", "—"]
            )
        lines.append(f"| {a['name']} | " + " | ".join(cells) + " |")
    return lines


def table_markdown(summary: dict[str, Any]) -> str:
    """table4.md: Table 4 beside the paper's, the generalisation figures and the transfer speed-up."""
    ev = summary["evaluation"]
    tail_headers, tail_cells = tail_columns(summary)
    lines = [
        "# Table 4: success rate and average cost",
        "",
        f"Grid `{summary['grid']}`. Every team flies the same {ev['episodes']} layouts of `{ev['scenario']}` "
        f"(layout seed {ev['seed']}, never used in training; {ev['layouts']}). Ours: mean ± sample standard "
        "deviation over the "
        "finished seeds. Success = the target was hit (all three tasks). Average cost = hazard cost per UAV "
        f"per mission (limit C = {summary['cost_limit']:g} per UAV); within C = the share of UAV-missions whose own "
        f"cost "
        "is at most C. The paper's figures are its Table 4.",
        "",
        _budget(summary["training"]),
        "",
        "| algorithm | seeds | success rate | average cost | within C | paper: success rate | paper: average cost | "
        + "".join(f"{h} | " for h in tail_headers)
        + "training wall time per seed |",
        "| --- | --- | --- | --- | --- | --- | --- | " + "--- | " * len(tail_headers) + "--- |",
    ]
    for a in summary["algorithms"]:
        paper = a["paper"]
        p_rate, p_cost = (f"{100 * paper['success_rate']:.0f}%", f"{paper['mean_cost']:.1f}") if paper else ("—", "—")
        r = a["random"]
        lines.append(
            f"| {a['name']} | {len(a['seeds'])} | {_rate(r['success_rate'])} | {_cost(r['mean_cost'])} "
            f"| {_rate(r['within_cost_limit'])} | {p_rate} | {p_cost} | "
            + "".join(f"{c} | " for c in tail_cells.get(a["name"], []))
            + f"{_minutes(a['training_wall_s'])} |"
        )
    g = summary["guidance"]["random"]
    lines.append(
        f"| {GUIDANCE_NAME} | — | {100 * g['success_rate']:.1f}% | {g['mean_cost']:.2f} | "
        f"{100 * g['within_cost_limit']:.1f}% | — | — | "
        + "".join(f"{c} | " for c in tail_cells.get(GUIDANCE_NAME, []))
        + "— |"
    )
    if tail_headers:
        lines += tail_markdown(summary)
    lines += [
        "",
        "## The mean cost against the limit",
        "",
        f"Every seed's {ev['episodes']} missions pooled: the mean cost per UAV per mission with a 95% bootstrap "
        f"interval over "
        "missions, how many UAV-missions cost more than C, and the largest single costs (steps of 0.1 s inside a "
        "radar). A "
        "few long stays inside a radar make the mean: where the interval spans C, these layouts cannot tell on which "
        "side of "
        "the limit the algorithm is.",
        "",
        "| algorithm | UAV-missions | mean cost | 95% interval | over C | largest |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for a in summary["algorithms"]:
        c = a["random"]["pooled_cost"]
        if c["mean"] is not None:
            largest = ", ".join(f"{v:.0f}" for v in c["largest"] if v > 0) or "—"
            lines.append(
                f"| {a['name']} | {c['uav_missions']} | {c['mean']:.2f} | {c['ci95'][0]:.2f}-{c['ci95'][1]:.2f} "
                f"| {c['over_limit']} | {largest} |"
            )
    if summary["left_out"]:
        lines += [
            "",
            f"Left out (not finished, or a run with other settings than the grid: see --dry-run): "
            f"{', '.join(summary['left_out'])}.",
        ]
    if "generalization" in summary["guidance"]:
        lines += [
            "",
            "## Generalisation (figure 11)",
            "",
            f"The same teams on `{ev['generalization_scenario']}` ({ev['episodes']} layouts, seed {ev['seed']}).",
            "",
            "| algorithm | seeds | success rate | average cost | within C |",
            "| --- | --- | --- | --- | --- |",
        ]
        for a in summary["algorithms"]:
            r = a["generalization"]
            lines.append(
                f"| {a['name']} | {len(a['seeds'])} | {_rate(r['success_rate'])} | {_cost(r['mean_cost'])} | "
                f"{_rate(r['within_cost_limit'])} |"
            )
        g = summary["guidance"]["generalization"]
        lines.append(
            f"| {GUIDANCE_NAME} | — | {100 * g['success_rate']:.1f}% | {g['mean_cost']:.2f} | "
            f"{100 * g['within_cost_limit']:.1f}% |"
        )
    t = summary["transfer_speedup"]
    lines += [
        "",
        "## Transfer inside the grid's curricula",
        "",
        f"Learner decisions (`env_steps` in metrics.csv) until the first epoch with task success >= "
        f"{100 * t['threshold']:.0f}%, "
        "mean over the finished seeds, in the grid's own runs (each role beside that run's earlier roles). A seed that "
        "never "
        "got there counts with its role's total decisions, so such a mean is a lower bound (>=)."
        + (
            " The transfer experiment (last section) measures it beside the same trained earlier roles."
            if summary.get("transfer_experiment")
            else ""
        ),
        "",
        "| role | tssac | sac_lag | speed-up (sac_lag / tssac) |",
        "| --- | --- | --- | --- |",
    ]
    for role in TRANSFER_ROLES:
        r = t[role]
        speedup = "—" if r["speedup"] is None else f"{'>= ' if r['speedup_is_lower_bound'] else ''}{r['speedup']:.2f}x"
        lines.append(f"| {role} | {_steps(r['tssac'])} | {_steps(r['sac_lag'])} | {speedup} |")
    lines += [
        "",
        "Task success in training averaged over the role's epochs (the area under its learning curve; mean ± "
        "standard deviation over seeds): with transfer, the role starts from the previous role's networks.",
        "",
        "| role | tssac (transfer) | sac_lag (from scratch) |",
        "| --- | --- | --- |",
    ]
    for role in TRANSFER_ROLES:
        r = t[role]
        lines.append(
            f"| {role} | {_rate(r['tssac']['mean_task_success'])} | {_rate(r['sac_lag']['mean_task_success'])} |"
        )
    if summary.get("transfer_experiment"):
        lines += transfer_experiment_markdown(summary["transfer_experiment"])
    return "\n".join(lines) + "\n"


def transfer_experiment_markdown(x: dict[str, Any]) -> list[str]:
    """The transfer experiment's table: decisions to the level per seed and their mean, each side, each role."""
    first = x[x["roles"][0]]
    with_name, without_name = first["with"]["entry"] or "with", first["without"]["entry"] or "without"
    cap = x["epochs"] * x["steps_per_epoch"]
    lines = [
        "",
        "## Transfer experiment: decisions to the level, with and without transfer",
        "",
        f"Each role trained alone with the same trained earlier roles flying (`{x['teammates']}`), stopped at the "
        f"first "
        f"epoch whose task success in training reached {100 * x['threshold']:.0f}%, at most {x['epochs']} epochs "
        f"({cap:,} decisions). `{with_name}` starts from the previous role's networks in `{x['teammates']}` (TSSAC's "
        f"transfer); "
        f"`{without_name}` starts from scratch. Per seed, then the mean; a seed that never got there counts with its "
        f"{cap:,} decisions, so such a mean is a lower bound (>=).",
        "",
        f"| role | {with_name} (transfer): per seed | mean | {without_name} (from scratch): per seed | mean | speed-up "
        f"|",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for role in x["roles"]:
        r = x[role]
        speed = "—" if r["speedup"] is None else f"{'>= ' if r['speedup_is_lower_bound'] else ''}{r['speedup']:.1f}x"
        lines.append(
            f"| {role} | {_per_seed(r['with'])} | {_mean_steps(r['with'])} | {_per_seed(r['without'])} | "
            f"{_mean_steps(r['without'])} | {speed} |"
        )
    return lines


def _per_seed(figures: dict[str, Any]) -> str:
    if not figures["seeds"]:
        return "—"
    return ", ".join(
        f"{v:,}" if v is not None else f"not in {figures['counted'][seed]:,}" for seed, v in figures["per_seed"].items()
    )


def _mean_steps(figures: dict[str, Any]) -> str:
    if figures["mean_steps"] is None:
        return "—"
    return f"{'>= ' if figures['mean_is_lower_bound'] else ''}{figures['mean_steps']:,.0f}"


def write_report(summary: dict[str, Any], results: Path) -> tuple[Path, Path]:
    """Write ``table4.md`` and ``experiments.json`` under ``results``."""
    results.mkdir(parents=True, exist_ok=True)
    table = results / "table4.md"
    tmp = table.with_name(table.name + ".tmp")
    tmp.write_text(table_markdown(summary))
    tmp.replace(table)
    data = results / "experiments.json"
    write_json(data, summary)
    return table, data
