"""Evaluate a grid's finished teams on the same layouts and write Table 4 (``table4.md``) and ``experiments.json``.

Every finished team, and the guidance controller as a reference row, flies the evaluation scenario's
layouts drawn from the grid's evaluation seed (the same layouts for every team), and the generalisation
scenario's if the grid names one. Each evaluation is cached as JSON next to the team
(``<run>/eval_random.json``, ``<run>/eval_generalization.json``; the guidance controller's under
``<results>/guidance/``) with the per-episode figures the box plots need; a cache is reused only if it was
made from the same checkpoints, scenario, seed and number of episodes.

Figures per algorithm are mean ± sample standard deviation over its finished seeds. The transfer speed-up
compares, for the detect and strike roles, the learner decisions (``env_steps`` in metrics.csv) until the
first epoch whose task success reaches 90%, TSSAC against SAC-Lagrangian, and the task success averaged
over the role's epochs (which also compares runs that never reach 90%).
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tssac_core.cli import write_json
from tssac_core.deploy.policy import checkpoint_info, load_team, read_checkpoint
from tssac_core.experiments.grid import Grid, Job
from tssac_core.sim.missions import MissionResults, fly_missions
from tssac_core.sim.scenario import ROLES, load
from tssac_core.sim.team import GUIDANCE, Pilot

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


@dataclass(frozen=True)
class EvalSpec:
    """One evaluation every team flies."""

    label: str
    """``random`` (Table 4, figure 10) or ``generalization`` (figure 11); names the cache file."""
    scenario: Path
    episodes: int
    seed: int

    def cache_name(self) -> str:
        return f"eval_{self.label}.json"


def eval_specs(grid: Grid) -> list[EvalSpec]:
    ev = grid.evaluation
    specs = [EvalSpec("random", ev.scenario, ev.episodes, ev.seed)]
    if ev.generalization_scenario is not None:
        specs.append(EvalSpec("generalization", ev.generalization_scenario, ev.episodes, ev.seed))
    return specs


def team_digest(team: Path) -> str:
    """A hash of what the three role checkpoints fly with (actor weights, observation mode, decision
    interval): a cached evaluation belongs to exactly these pilots, also after ``--compact``."""
    h = hashlib.sha256()
    for role in ROLES:
        path = team / f"{role.value}.pt"
        data = read_checkpoint(path)
        info = checkpoint_info(data, path)
        h.update(f"{info.role.value} {info.observation_mode.value} {info.action_repeat} {info.hidden_sizes}".encode())
        for name, tensor in sorted(data["actor"].items()):
            h.update(name.encode())
            h.update(tensor.detach().cpu().numpy().tobytes())
    return h.hexdigest()[:16]


def evaluate(team: Path | None, spec: EvalSpec, cache: Path) -> dict[str, Any]:
    """The summary of ``team`` (None: the guidance controller) flying ``spec``, from ``cache`` if it still fits.

    The summary has the keys of ``tssac_core.evaluate --json`` plus ``per_episode``: ``success`` (M,),
    ``return`` and ``cost`` (M, 3) per role.
    """
    scenario = load(spec.scenario)
    key = {
        "team": team_digest(team) if team is not None else GUIDANCE,
        "scenario_digest": scenario.digest(),
        "seed": spec.seed,
        "episodes": spec.episodes,
    }
    if cache.is_file():
        try:
            cached = json.loads(cache.read_text())
        except ValueError:
            cached = {}
        if cached.get("cache_key") == key and "per_episode" in cached:
            return dict(cached)
    pilots: list[Pilot] = list(load_team(team)) if team is not None else [GUIDANCE] * len(ROLES)
    results = fly_missions(scenario, pilots, spec.episodes, spec.seed)
    summary = results.summary(scenario.cost_limit)
    summary.update(
        {
            "controller": str(team) if team is not None else GUIDANCE,
            "scenario": str(spec.scenario),
            "seed": spec.seed,
            "cost_limit": scenario.cost_limit,
            "cache_key": key,
            "per_episode": {
                "success": results.success.tolist(),
                "return": results.returns.tolist(),
                "cost": results.cost.tolist(),
            },
        }
    )
    write_json(cache, summary)
    return summary


def fly_one(team: Path, spec: EvalSpec) -> MissionResults:
    """The first evaluation layout, flown by ``team`` with its trajectories recorded (figure 9)."""
    scenario = load(spec.scenario)
    return fly_missions(scenario, list(load_team(team)), 1, spec.seed, record=True)


Evaluations = dict[tuple[str, str], dict[str, Any]]
"""(job name or GUIDANCE, eval label) -> evaluation summary."""


def within_limit(evaluation: dict[str, Any]) -> float:
    """The share of UAV-missions (every role of every mission) whose hazard cost is within the scenario's
    limit: how often the constraint held, beside the mean that one long stay inside a radar can dominate."""
    return float(np.mean(np.asarray(evaluation["per_episode"]["cost"]) <= evaluation["cost_limit"]))


BOOTSTRAP_RESAMPLES = 10_000


def pooled_cost(evaluations: list[dict[str, Any]], resamples: int = BOOTSTRAP_RESAMPLES) -> dict[str, Any]:
    """The mean hazard cost per UAV per mission over every seed's missions pooled, with a 95% percentile
    bootstrap interval over missions (a mission's three UAVs resampled together; fixed resampling seed),
    the UAV-missions over the limit and the largest single costs.

    A mean cost near the limit C = 3 is made of rare long stays inside a radar (one of 500-800 steps is
    a whole evaluation's mean of 3-5), so a 50-layout mean alone cannot say on which side of C a policy is;
    the interval says how far the figure can be trusted."""
    if not evaluations:
        return {"uav_missions": 0, "mean": None, "ci95": None, "over_limit": 0, "largest": []}
    costs = np.concatenate([np.asarray(e["per_episode"]["cost"], dtype=np.float64) for e in evaluations])  # (M, 3)
    per_mission = costs.mean(axis=1)
    idx = np.random.default_rng(0).integers(0, len(per_mission), size=(resamples, len(per_mission)))
    low, high = np.percentile(per_mission[idx].mean(axis=1), [2.5, 97.5])
    limit = evaluations[0]["cost_limit"]
    return {
        "uav_missions": int(costs.size),
        "mean": float(costs.mean()),
        "ci95": [float(low), float(high)],
        "over_limit": int((costs > limit).sum()),
        "largest": sorted(costs.ravel().tolist(), reverse=True)[:3],
    }


def evaluate_all(grid: Grid, finished: list[Job], results: Path, report: Callable[[str], None]) -> Evaluations:
    """Every finished team and the guidance controller on every EvalSpec (cached)."""
    out: Evaluations = {}
    for spec in eval_specs(grid):
        report(f"evaluating on {spec.scenario.name}: {spec.episodes} layouts, seed {spec.seed}")
        out[(GUIDANCE, spec.label)] = evaluate(None, spec, results / "guidance" / spec.cache_name())
        for job in finished:
            out[(job.name, spec.label)] = evaluate(job.out, spec, job.out / spec.cache_name())
    return out


# ------------------------------------------------------------------------------------ figures


def over_seeds(per_seed: dict[int, float]) -> dict[str, Any]:
    """Mean and sample standard deviation over seeds (std None with fewer than two)."""
    values = list(per_seed.values())
    return {
        "mean": float(np.mean(values)) if values else None,
        "std": float(np.std(values, ddof=1)) if len(values) > 1 else None,
        "per_seed": {str(s): v for s, v in per_seed.items()},
    }


INVOCATION_LINE = re.compile(r"^trained .* in (\d+) s; results in |^=== .* runner: stopped after (\d+) s", re.MULTILINE)
"""The line ``tssac_core.train`` prints when it finishes, and the one the grid runner writes when it stops a job."""
PAPER_EPOCHS = 50
"""Table 3: epochs per role."""


def training_wall_s(run: Path) -> float | None:
    """Wall seconds of a run by its train.log: summed over its invocations, those that finished (the "trained
    ... in N s" line of ``tssac_core.train``) and those the grid runner stopped ("stopped after N s", the
    epoch they were in included: it was spent, though it is trained again). An invocation killed some other
    way leaves no line, and its time is not counted."""
    log = run / "train.log"
    if not log.is_file():
        return None
    seconds = [int(done or stopped) for done, stopped in INVOCATION_LINE.findall(log.read_text(errors="replace"))]
    return float(sum(seconds)) if seconds else None


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
    transfer_runs: list[Job] = (),
) -> dict[str, Any]:
    """Everything ``experiments.json`` holds."""
    labels = [spec.label for spec in eval_specs(grid)]
    algorithms = []
    for entry in grid.algos:
        mine = [j for j in finished if j.entry == entry]
        row: dict[str, Any] = {
            "name": entry.name,
            "algo": entry.algo,
            "penalty": entry.penalty,
            "seeds": [j.seed for j in mine],
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
    guidance = {
        label: {
            **{key: evaluations[(GUIDANCE, label)][key] for key in ("success_rate", "mean_cost", "episodes")},
            "within_cost_limit": within_limit(evaluations[(GUIDANCE, label)]),
        }
        for label in labels
    }
    ev = grid.evaluation
    return {
        "grid": shown(grid.source),
        "results": shown(results),
        "evaluation": {
            "scenario": shown(ev.scenario),
            "episodes": ev.episodes,
            "seed": ev.seed,
            "generalization_scenario": shown(ev.generalization_scenario) if ev.generalization_scenario else None,
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


def table_markdown(summary: dict[str, Any]) -> str:
    """table4.md: Table 4 beside the paper's, the generalisation figures and the transfer speed-up."""
    ev = summary["evaluation"]
    lines = [
        "# Table 4: success rate and average cost",
        "",
        f"Grid `{summary['grid']}`. Every team flies the same {ev['episodes']} layouts of `{ev['scenario']}` "
        f"(layout seed {ev['seed']}, never used in training). Ours: mean ± sample standard deviation over the "
        "finished seeds. Success = the target was hit (all three tasks). Average cost = hazard cost per UAV "
        f"per mission (limit C = {summary['cost_limit']:g} per UAV); within C = the share of UAV-missions whose own "
        f"cost "
        "is at most C. The paper's figures are its Table 4.",
        "",
        _budget(summary["training"]),
        "",
        "| algorithm | seeds | success rate | average cost | within C | paper: success rate | paper: average cost | "
        "training wall time per seed |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for a in summary["algorithms"]:
        paper = a["paper"]
        p_rate, p_cost = (f"{100 * paper['success_rate']:.0f}%", f"{paper['mean_cost']:.1f}") if paper else ("—", "—")
        r = a["random"]
        lines.append(
            f"| {a['name']} | {len(a['seeds'])} | {_rate(r['success_rate'])} | {_cost(r['mean_cost'])} "
            f"| {_rate(r['within_cost_limit'])} | {p_rate} | {p_cost} | {_minutes(a['training_wall_s'])} |"
        )
    g = summary["guidance"]["random"]
    lines.append(
        f"| {GUIDANCE_NAME} | — | {100 * g['success_rate']:.1f}% | {g['mean_cost']:.2f} | "
        f"{100 * g['within_cost_limit']:.1f}% | — | — | — |"
    )
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
