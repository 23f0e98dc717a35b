"""Time to solution: how long a curriculum trained until the team it ships, from its metrics files.

    python benchmarks/time_to_solution.py [RUN_DIR ...] [--json benchmarks/results/time_to_solution.json]

For each run directory (default: the shipped team, ``models/tssac``) this reads ``metrics.csv`` (one
row per role and epoch, written by ``python -m tssac_core.train``) and adds up each epoch's training
time, ``env steps / env_steps_per_s + updates / updates_per_s`` (the loop's own timers: acting,
stepping the worlds, gradient updates). The curriculum trains every epoch of a role before the next
role starts, and ships each role's best validated epoch (``best_epoch``), so the team it ships exists
once the last role has trained its shipped epoch: that point is the time to solution. The held-out
validation flown after every epoch is not in the timers; it is estimated from the run's whole wall
time (``trained ... in N s`` in ``train.log``, or ``--wall-s``) where known, in proportion to epochs.

The quality of the shipped team comes from ``eval_random.json`` beside the metrics
(``python -m tssac_core.evaluate --models RUN_DIR --scenario scenarios/random.yaml --episodes 50
--seed 12345 --json RUN_DIR/eval_random.json``). Target (issue 8): under 60 minutes to a team with
>= 95% mission success.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # for benchmarks.output
from benchmarks.output import add_json_option  # noqa: E402
from tssac_core.common.cli import command_description

ROOT = Path(__file__).resolve().parent.parent
TARGET_MIN = 60.0
TARGET_SUCCESS = 0.95


def epoch_seconds(rows: list[dict[str, str]]) -> list[tuple[str, int, float]]:
    """(role, epoch, training seconds) per row, from the loop's rates and the steps and updates the epoch added."""
    out: list[tuple[str, int, float]] = []
    last: dict[str, tuple[int, int]] = {}
    for r in rows:
        role = r["role"]
        steps0, updates0 = last.get(role, (0, 0))
        steps, updates = int(float(r["env_steps"])), int(float(r["updates"]))
        last[role] = (steps, updates)
        env_rate, update_rate = float(r["env_steps_per_s"]), float(r["updates_per_s"] or "nan")
        seconds = (steps - steps0) / env_rate
        if updates > updates0 and math.isfinite(update_rate) and update_rate > 0:
            seconds += (updates - updates0) / update_rate
        out.append((role, int(r["epoch"]), seconds))
    return out


def reported_wall_s(run: Path) -> float | None:
    """The run's wall time as the training command printed it (summed over resumed invocations)."""
    log = run / "train.log"
    if not log.is_file():
        return None
    found = [
        int(s)
        for s in re.findall(r"^trained .* in (\d+) s; results in ", log.read_text(errors="replace"), re.MULTILINE)
    ]
    return float(sum(found)) if found else None


def time_to_solution(run: Path, wall_s: float | None = None) -> dict[str, Any]:
    with (run / "metrics.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise SystemExit(f"{run / 'metrics.csv'}: no epochs")
    per_epoch = epoch_seconds(rows)
    roles = list(dict.fromkeys(role for role, _, _ in per_epoch))
    last_role = roles[-1]
    shipped = int(float([r for r in rows if r["role"] == last_role][-1]["best_epoch"] or 0)) or max(
        e for ro, e, _ in per_epoch if ro == last_role
    )
    until = 0
    for i, (role, epoch, _) in enumerate(per_epoch):
        if role == last_role and epoch == shipped:
            until = i + 1
            break
    training_total = sum(s for _, _, s in per_epoch)
    training_to_solution = sum(s for _, _, s in per_epoch[:until])
    wall = wall_s if wall_s is not None else reported_wall_s(run)
    result: dict[str, Any] = {
        "run": str(run),
        "roles": roles,
        "epochs": len(per_epoch),
        "shipped_epoch_of_last_role": shipped,
        "epochs_to_solution": until,
        "training_s_total": training_total,
        "training_s_to_solution": training_to_solution,
        "wall_s_total": wall,
    }
    if wall is not None:
        validation_per_epoch = max(0.0, wall - training_total) / len(per_epoch)
        result["wall_s_to_solution_estimate"] = training_to_solution + validation_per_epoch * until
    evaluation = run / "eval_random.json"
    if evaluation.is_file():
        ev = json.loads(evaluation.read_text())
        result["shipped_team"] = {
            "success_rate": ev["success_rate"],
            "mean_cost": ev["mean_cost"],
            "episodes": ev["episodes"],
        }
    return result


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    p.add_argument(
        "runs", nargs="*", type=Path, default=[ROOT / "models" / "tssac"], help="run directories (default models/tssac)"
    )
    p.add_argument(
        "--wall-s", type=float, help="the run's whole wall time, if its train.log is not there (one run only)"
    )
    add_json_option(p, "time_to_solution")
    a = p.parse_args(argv)
    if a.wall_s is not None and len(a.runs) != 1:
        raise SystemExit("--wall-s applies to one run")
    results = []
    for run in a.runs:
        r = time_to_solution(run, a.wall_s)
        results.append(r)
        team = r.get("shipped_team")
        quality = (
            f"shipped team {100 * team['success_rate']:.0f}% success, cost {team['mean_cost']:.2f}"
            if team
            else "no eval_random.json"
        )
        wall = (
            f"; with validation ~{r['wall_s_to_solution_estimate'] / 60:.1f} min"
            if "wall_s_to_solution_estimate" in r
            else ""
        )
        print(
            f"{run}: {r['epochs_to_solution']} of {r['epochs']} epochs, training "
            f"{r['training_s_to_solution'] / 60:.1f} min "
            f"to the shipped team{wall} (target < {TARGET_MIN:.0f} min at >= {100 * TARGET_SUCCESS:.0f}%); {quality}"
        )
    a.json.parent.mkdir(parents=True, exist_ok=True)
    a.json.write_text(
        json.dumps({"target_minutes": TARGET_MIN, "target_success": TARGET_SUCCESS, "runs": results}, indent=2) + "\n"
    )
    print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
