"""The cross-check's results file: one row per (implementation, algorithm, seed), written as soon as the row is
finished and skipped on a rerun (so the long job can span sessions); pooling the seeds; the markdown table.

A row holds its setting (budget, evaluation layouts, C), its figures with 95% intervals (Wilson for the task
success and the within-C share, bootstrap over missions for the mean cost: tssac_core.common.stats), the
per-mission outcomes (so the pooled figures are computed from the missions, not from per-seed figures), the
training wall time and the exact commands.
"""

from __future__ import annotations

import fcntl
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.crosscheck.settings import ALGOS, IMPLS, Budget, Job
from tssac_core.common.cli import write_json
from tssac_core.common.stats import bootstrap_mean_interval, wilson_interval

FORMAT = "tssac-crosscheck-rows"


class RowsError(ValueError):
    """A results file that cannot be used as asked (one line for the command)."""


def setting(budget: Budget, episodes: int, eval_seed: int, cost_limit: float) -> dict[str, Any]:
    """What a row was made with; a rerun must match it to reuse the row."""
    return {
        "epochs": budget.epochs,
        "steps_per_epoch": budget.steps_per_epoch,
        "eval_episodes": episodes,
        "eval_seed": eval_seed,
        "cost_limit": cost_limit,
    }


def figures(task_done: Sequence[bool], cost: Sequence[float], cost_limit: float) -> dict[str, Any]:
    """Task success and within-C share (Wilson 95%) and mean cost per UAV-mission (bootstrap 95%)."""
    if len(task_done) != len(cost) or not cost:
        raise RowsError(f"need as many task outcomes as costs, at least one: got {len(task_done)} and {len(cost)}")
    c = np.asarray(cost, dtype=np.float64)
    n = len(c)
    return {
        "missions": n,
        "task_success": wilson_interval(int(np.sum(task_done)), n).as_dict(),
        "mean_cost": bootstrap_mean_interval(c).as_dict(),
        "within_c": wilson_interval(int(np.sum(c <= cost_limit)), n).as_dict(),
    }


def make_row(
    job: Job,
    the_setting: dict[str, Any],
    task_done: Sequence[bool],
    cost: Sequence[float],
    train_wall_s: float,
    eval_wall_s: float,
    commands: list[list[str]],
    run_dir: str,
) -> dict[str, Any]:
    decisions = the_setting["epochs"] * the_setting["steps_per_epoch"]
    return {
        "impl": job.impl,
        "algo": job.algo,
        "omnisafe_algo": ALGOS[job.algo],
        "seed": job.seed,
        "setting": the_setting,
        **figures(task_done, cost, the_setting["cost_limit"]),
        "train_wall_s": round(train_wall_s, 2),
        "ms_per_decision": round(1000.0 * train_wall_s / decisions, 3),
        "eval_wall_s": round(eval_wall_s, 2),
        "commands": commands,
        "run_dir": run_dir,
        "per_mission": {"task_done": [bool(x) for x in task_done], "cost": [float(x) for x in cost]},
    }


class RowStore:
    """The rows of one results file (JSON: {"format": FORMAT, "rows": [...]}). Every ``done`` reads the file again
    and every ``add`` reads, appends and rewrites it atomically under a lock (``<file>.lock``), so commands run side
    by side (say one per algorithm) can share one file without losing each other's rows."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.rows: list[dict[str, Any]] = []
        self.reload()

    def reload(self) -> None:
        if not self.path.exists():
            self.rows = []
            return
        try:
            data = json.loads(self.path.read_text())
        except ValueError as exc:
            raise RowsError(f"{self.path}: not JSON ({exc})") from None
        if not isinstance(data, dict) or data.get("format") != FORMAT or not isinstance(data.get("rows"), list):
            raise RowsError(f"{self.path}: not a cross-check results file (format {FORMAT})")
        self.rows = data["rows"]

    def find(self, job: Job) -> dict[str, Any] | None:
        for row in self.rows:
            if (row["impl"], row["algo"], row["seed"]) == (job.impl, job.algo, job.seed):
                return row
        return None

    def done(self, job: Job, the_setting: dict[str, Any]) -> bool:
        """Whether ``job``'s row is there; RowsError if it was made with another setting (a rerun must not mix)."""
        self.reload()
        row = self.find(job)
        if row is None:
            return False
        if row["setting"] != the_setting:
            raise RowsError(
                f"{self.path} holds {job.name} made with {row['setting']}, not {the_setting}: use another --rows"
            )
        return True

    def add(self, row: dict[str, Any]) -> None:
        job = Job(row["impl"], row["algo"], row["seed"])
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self.path.with_name(self.path.name + ".lock").open("w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            self.reload()
            if self.find(job) is not None:
                raise RowsError(f"{self.path} already holds {job.name}")
            self.rows.append(row)
            write_json(self.path, {"format": FORMAT, "rows": self.rows})


def pool(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One entry per (implementation, algorithm): the seeds' missions pooled (figures over all of them), the
    per-seed task success and mean cost, the mean training time. Ordered by algorithm, then implementation."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault((row["impl"], row["algo"]), []).append(row)
    order = {(i, a): (list(ALGOS).index(a), IMPLS.index(i)) for i in IMPLS for a in ALGOS}
    pooled = []
    for (impl, algo), group in sorted(groups.items(), key=lambda kv: order.get(kv[0], (99, 99))):
        settings = {json.dumps(r["setting"], sort_keys=True) for r in group}
        if len(settings) > 1:
            raise RowsError(f"{impl} {algo}: rows made with different settings cannot be pooled")
        group = sorted(group, key=lambda r: r["seed"])
        task = [t for r in group for t in r["per_mission"]["task_done"]]
        cost = [c for r in group for c in r["per_mission"]["cost"]]
        pooled.append(
            {
                "impl": impl,
                "algo": algo,
                "seeds": [r["seed"] for r in group],
                "setting": group[0]["setting"],
                **figures(task, cost, group[0]["setting"]["cost_limit"]),
                "per_seed_task_success": [r["task_success"]["value"] for r in group],
                "per_seed_mean_cost": [r["mean_cost"]["value"] for r in group],
                "train_wall_s": float(np.mean([r["train_wall_s"] for r in group])),
                "ms_per_decision": float(np.mean([r["ms_per_decision"] for r in group])),
                "cpu_ms_per_decision": mean_of([r.get("cpu_ms_per_decision") for r in group]),
            }
        )
    return pooled


def mean_of(values: Sequence[float | None]) -> float | None:
    """The mean of the values that are there (a row trained in an earlier invocation has no CPU figure)."""
    there = [v for v in values if v is not None]
    return float(np.mean(there)) if there else None


def _pct(interval: dict[str, float]) -> str:
    return f"{100 * interval['value']:.1f}% ({100 * interval['low']:.1f}-{100 * interval['high']:.1f})"


def table(pooled: Sequence[dict[str, Any]]) -> str:
    """The markdown table of ``pool``'s entries, with the setting they share in a line above it."""
    if not pooled:
        raise RowsError("no rows to report")
    s = pooled[0]["setting"]
    head = (
        f"Detect role beside the shipped decoy, trained for {s['epochs']} x {s['steps_per_epoch']:,} decisions of 1 s "
        f"(epochs x decisions per epoch); "
        f"{s['eval_episodes']} evaluation layouts per seed (layout seeds {s['eval_seed']}-"
        f"{s['eval_seed'] + s['eval_episodes'] - 1}), pooled over the seeds; 95% intervals (Wilson; bootstrap for "
        f"the mean cost); C = {s['cost_limit']:g} world steps per UAV-mission. Train s: the learner's wall time; "
        f"CPU ms: the training command's CPU time (start-up included) per decision.\n\n"
    )
    lines = [
        "| Algorithm | Implementation | Seeds | Detect task success | Mean cost per UAV-mission | Within C | "
        "Per-seed task success | Train s per run | CPU ms per decision |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for p in pooled:
        if p["setting"] != s:
            raise RowsError("rows made with different settings cannot share a table")
        c = p["mean_cost"]
        cpu = "n/a" if p["cpu_ms_per_decision"] is None else f"{p['cpu_ms_per_decision']:.1f}"
        per_seed = ", ".join(f"{100 * v:.0f}%" for v in p["per_seed_task_success"])
        lines.append(
            f"| {p['algo']} | {p['impl']} | {len(p['seeds'])} | {_pct(p['task_success'])} | "
            f"{c['value']:.2f} ({c['low']:.2f}-{c['high']:.2f}) | {_pct(p['within_c'])} | {per_seed} | "
            f"{p['train_wall_s']:.0f} | {cpu} |"
        )
    return head + "\n".join(lines) + "\n"
