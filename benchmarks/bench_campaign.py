"""SITL campaigns side by side: the same lockstep missions flown by ``fly`` from two (or more) checkouts, or from this
checkout with different ``fly`` arguments.

Each checkout (``--tree NAME=DIR``, e.g. today's main in a ``git worktree`` and this tree) or variant of this one
(``--variant NAME=ARGS``, e.g. ``jsbsim="--dynamics jsbsim"``: the physics backends side by side) flies the same
missions (``--scenario``, ``--models``, ``--seed``, ``--missions``) with ``--workers`` 1 and 2; the runs of the
trees alternate, so that a machine's noise hits them alike. Per run it reports:

* missions per hour: missions / the whole command's wall time (start-up, Ray and the missions' ends included);
* CPU seconds per simulated second: the CPU of every mission's processes over its simulated time;
* x real time in flight: simulated time / the companions' flight wall time (median over missions);
* per-step latency p50 / p99: a companion's fix-in to setpoint-out time (median of p50, max of p99);
* success and mean cost, which must agree across trees;

and, with ``--compare-truth``, whether every mission's truth log has the same step rows in every tree.

With ``--repeats K`` each tree flies K times per worker count, the trees in turn and in the reverse order every
other time (this machine gave the third slot of a run the slowest figure twice), and each figure is the median over
the repeats (``missions_per_hour_each`` keeps every run's).

    git worktree add --detach /tmp/main-tree main
    python benchmarks/bench_campaign.py --tree main=/tmp/main-tree --tree new=. --missions 20 \\
        --json benchmarks/results/campaign.json
    python benchmarks/bench_campaign.py --variant kinematic="--dynamics kinematic" \\
        --variant jsbsim="--dynamics jsbsim" --missions 100 --workers 2 --json /tmp/dynamics.json

Ratios are quoted against the first tree.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from tssac_core.common.cli import command_description

ROOT = Path(__file__).resolve().parents[1]


def fly(tree: Path, args: argparse.Namespace, workers: int, out: Path, extra: list[str]) -> dict[str, Any]:
    """One campaign from ``tree`` (with the variant's ``extra`` fly arguments); the fly JSON plus the command's wall
    time."""
    argv = [sys.executable, "-m", "mavlink_bridge.fly", "--scenario", str(args.scenario.resolve())]
    argv += ["--models", str(args.models.resolve()), "--episodes", str(args.missions), "--seed", str(args.seed)]
    argv += ["--lockstep", "--workers", str(workers), "--json", str(out / "fly.json"), "--logs", str(out / "logs")]
    argv += ["--no-progress", *args.fly_arg, *extra]
    env = dict(os.environ, PYTHONPATH=str(tree))
    t0 = time.monotonic()
    proc = subprocess.run(argv, cwd=tree, env=env, capture_output=True, text=True, timeout=args.timeout_s)
    wall = time.monotonic() - t0
    if proc.returncode != 0:
        raise SystemExit(f"bench_campaign: fly from {tree} failed (exit {proc.returncode}): {proc.stderr[-1500:]}")
    result = json.loads((out / "fly.json").read_text())
    result["command_wall_s"] = wall
    return result


def figures(result: dict[str, Any]) -> dict[str, Any]:
    missions = result["missions"]
    sim = sum(m["sim_time_s"] for m in missions)
    cpu = [m.get("cpu_s") for m in missions]
    companions = [c for m in missions for c in m["companions"].values()]
    p50 = [c["latency_p50_ms"] for c in companions if c.get("latency_p50_ms") is not None]
    p99 = [c["latency_p99_ms"] for c in companions if c.get("latency_p99_ms") is not None]
    speed = [m["speed_x"] for m in missions if m.get("speed_x")]
    return {
        "missions": len(missions),
        "command_wall_s": round(result["command_wall_s"], 2),
        "missions_per_hour": round(len(missions) / result["command_wall_s"] * 3600.0, 1),
        "mission_wall_s_mean": round(float(np.mean([m["wall_time_s"] for m in missions])), 3),
        "cpu_s_per_sim_s": None if None in cpu else round(sum(cpu) / sim, 5),
        "speed_x_in_flight_median": round(float(np.median(speed)), 1) if speed else None,
        "latency_p50_ms": round(float(np.median(p50)), 3) if p50 else None,
        "latency_p99_ms": round(float(np.max(p99)), 3) if p99 else None,
        "success_rate": result["success_rate"],
        "mean_cost": result["mean_cost"],
        "steps": [m.get("steps") for m in missions],
    }


MEDIAN_KEYS = (
    "command_wall_s",
    "missions_per_hour",
    "mission_wall_s_mean",
    "cpu_s_per_sim_s",
    "speed_x_in_flight_median",
    "latency_p50_ms",
    "latency_p99_ms",
)


def median_figures(repeats: list[dict[str, Any]]) -> dict[str, Any]:
    """Several runs of one tree as one row: the median of each figure, every run's missions per hour."""
    out = dict(repeats[0])
    for key in MEDIAN_KEYS:
        values = [r[key] for r in repeats if r[key] is not None]
        out[key] = round(float(np.median(values)), 5) if values else None
    out["missions_per_hour_each"] = [r["missions_per_hour"] for r in repeats]
    return out


def truth_steps(logs: Path) -> dict[str, list[str]]:
    """Every mission's step rows (as written), by mission directory."""
    out = {}
    for mission in sorted(logs.glob("mission-*")):
        lines = (mission / "truth.jsonl").read_text().splitlines()
        out[mission.name] = [line for line in lines if '"type": "step"' in line or '"type":"step"' in line]
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    p.add_argument("--tree", action="append", default=[], metavar="NAME=DIR", help="a checkout to fly from")
    p.add_argument(
        "--variant", action="append", default=[], metavar="NAME=ARGS", help="this checkout with these fly arguments"
    )
    p.add_argument("--missions", type=int, default=20, help="missions per run (default 20)")
    p.add_argument("--workers", default="1,2", help="comma-separated worker counts (default 1,2)")
    p.add_argument("--scenario", type=Path, default=ROOT / "scenarios" / "random.yaml")
    p.add_argument("--models", type=Path, default=ROOT / "models" / "tssac")
    p.add_argument("--seed", type=int, default=5000)
    p.add_argument("--fly-arg", action="append", default=[], help="one more fly argument for every tree")
    p.add_argument("--compare-truth", action="store_true", help="check the truth logs' step rows across trees")
    p.add_argument("--repeats", type=int, default=1, help="runs per tree and worker count, in alternating order")
    p.add_argument("--timeout-s", type=float, default=7200.0)
    p.add_argument("--json", type=Path, help="write the figures here")
    args = p.parse_args(argv)
    trees: dict[str, Path] = {}
    extras: dict[str, list[str]] = {}
    for spec in args.tree:
        name, sep, path = spec.partition("=")
        if not sep or not Path(path).is_dir():
            p.error(f"--tree {spec!r}: expected NAME=DIR with an existing DIR")
        trees[name], extras[name] = Path(path).resolve(), []
    for spec in args.variant:
        name, sep, fly_args = spec.partition("=")
        if not sep or name in trees:
            p.error(f"--variant {spec!r}: expected NAME=ARGS with a name of its own")
        trees[name], extras[name] = ROOT, fly_args.split()
    if len(trees) < 1:
        p.error("give at least one --tree or --variant")
    report: dict[str, Any] = {
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()},
        "missions": args.missions,
        "scenario": str(args.scenario),
        "seed": args.seed,
        "repeats": args.repeats,
        "variants": {name: " ".join(extra) for name, extra in extras.items() if extra},
        "runs": {},
    }
    with tempfile.TemporaryDirectory(prefix="bench-campaign-") as tmp:
        for workers in [int(w) for w in args.workers.split(",")]:
            each: dict[str, list[dict[str, Any]]] = {name: [] for name in trees}
            steps: dict[str, list[dict[str, list[str]]]] = {name: [] for name in trees}
            for repeat in range(args.repeats):
                order = list(trees) if repeat % 2 == 0 else list(reversed(trees))
                for name in order:
                    out = Path(tmp) / f"{name}-w{workers}-r{repeat}"
                    out.mkdir()
                    each[name].append(figures(fly(trees[name], args, workers, out, extras[name])))
                    if args.compare_truth:
                        steps[name].append(truth_steps(out / "logs"))
                    shown = {k: v for k, v in each[name][-1].items() if k != "steps"}
                    print(f"workers={workers} {name} (run {repeat + 1}): {json.dumps(shown)}", flush=True)
            runs = {name: median_figures(each[name]) for name in trees}
            first = next(iter(trees))
            for name in trees:
                runs[name]["missions_per_hour_ratio"] = round(
                    runs[name]["missions_per_hour"] / runs[first]["missions_per_hour"], 2
                )
                if args.compare_truth:
                    runs[name]["truth_steps_equal_to_" + first] = all(s == steps[first][0] for s in steps[name])
            report["runs"][f"workers={workers}"] = runs
    print()
    print(
        "| workers | tree | missions/h | each run | x first | mission wall s | CPU s per sim s | x real time | p50 ms "
        "| p99 ms |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for key, runs in report["runs"].items():
        for name, f in runs.items():
            each = ", ".join(f"{m:g}" for m in f["missions_per_hour_each"])
            print(
                f"| {key.split('=')[1]} | {name} | {f['missions_per_hour']:g} | {each} | "
                f"{f['missions_per_hour_ratio']} | {f['mission_wall_s_mean']} | {f['cpu_s_per_sim_s']} | "
                f"{f['speed_x_in_flight_median']} | {f['latency_p50_ms']} | {f['latency_p99_ms']} |"
            )
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
