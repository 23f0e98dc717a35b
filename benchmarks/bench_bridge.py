"""Measure the MAVLink bridge: control-loop latency and whole missions per minute in lockstep.

Runs ``python -m mavlink_bridge.fly`` (a SITL world plus three companion processes per mission, in
lockstep) with the guidance pilot, and with the trained policies if ``--models`` (default
``models/tssac``) holds them, and reports:

* latency: wall time from a telemetry datagram read by a companion to the setpoint it sent in
  response (filter update, observation, pilot, setpoint encode and send), pooled over every control
  step of every companion: p50, p99, max (target: p99 < 5 ms);
* missions per minute (whole runs: process start-up included) and the speed of a mission relative
  to real time, for the whole mission and for its flight alone (target: >= 50x);
* CPU: seconds used by the mission's processes (world + 3 companions), and the machine's other load
  during the run (from /proc/stat), because on a shared machine the wall-clock figures measure the
  neighbours as much as the bridge. ``idle_machine_speed_x_bound`` = simulated time / (mission CPU /
  CPUs) is what the same work could reach with every CPU to itself (an upper bound).

    python benchmarks/bench_bridge.py [--episodes 3] [--scenario scenarios/strike.yaml] \
        [--models models/tssac] [--full-telemetry] [--json benchmarks/results/bridge.json]
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
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # for benchmarks.output
from benchmarks.output import add_json_option, write_figures  # noqa: E402
from tssac_core.common.cli import command_description

REPO = Path(__file__).resolve().parents[1]
TARGET_P99_MS = 5.0
TARGET_SPEED_X = 50.0


def _cpu_ticks() -> tuple[int, int]:
    """(busy, total) jiffies of the whole machine."""
    fields = [int(x) for x in Path("/proc/stat").read_text().splitlines()[0].split()[1:]]
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)
    return sum(fields) - idle, sum(fields)


def run_fly(
    scenario: Path, episodes: int, models: Path | None, work: Path, extra: Sequence[str] = ()
) -> dict[str, Any]:
    """One fly run; its JSON, the pooled latency samples and the machine load during it."""
    out = work / "fly.json"
    logs = work / "logs"
    who = ["--models", str(models)] if models is not None else ["--pilot", "guidance"]
    argv = [
        sys.executable,
        "-m",
        "mavlink_bridge.fly",
        "--scenario",
        str(scenario),
        *who,
        "--lockstep",
        "--episodes",
        str(episodes),
        "--seed",
        "0",
        "--json",
        str(out),
        "--logs",
        str(logs),
        "--no-progress",
        *extra,
    ]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    busy0, total0 = _cpu_ticks()
    t0 = time.monotonic()
    proc = subprocess.run(argv, capture_output=True, text=True, cwd=REPO, env=env)
    wall_s = time.monotonic() - t0
    busy1, total1 = _cpu_ticks()
    if proc.returncode != 0:
        raise SystemExit(
            f"fly failed ({proc.returncode}): {proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else ''}"
        )
    results = json.loads(out.read_text())
    samples: list[float] = []
    for status in sorted(logs.glob("mission-*/*.status.json")):
        samples += json.loads(status.read_text()).get("latency_samples_ms", [])
    hz = os.sysconf("SC_CLK_TCK")
    machine_busy_s = (busy1 - busy0) / hz
    cpus = os.cpu_count() or 1
    return {
        "results": results,
        "samples": samples,
        "wall_s": wall_s,
        "machine_busy_s": machine_busy_s,
        "machine_capacity_s": (total1 - total0) / hz,
        "cpus": cpus,
    }


def summarise(name: str, run: dict[str, Any]) -> dict[str, Any]:
    res = run["results"]
    missions = res["missions"]
    lat = np.asarray(run["samples"])
    sim = np.array([m["sim_time_s"] for m in missions])
    wall = np.array([m["wall_time_s"] for m in missions])
    flight = np.array([m.get("flight_wall_s") or np.nan for m in missions])
    cpu = np.array([m["cpu_s"] for m in missions])
    flight_cpu = np.array([m.get("flight_cpu_s") or np.nan for m in missions])
    ours = float(cpu.sum())
    other = max(0.0, run["machine_busy_s"] - ours)
    return {
        "pilot": name,
        "episodes": len(missions),
        "success_rate": res["success_rate"],
        "mean_cost": res["mean_cost"],
        "latency_ms": {
            "n": int(lat.size),
            "p50": float(np.percentile(lat, 50)),
            "p99": float(np.percentile(lat, 99)),
            "max": float(lat.max()),
            "target_p99": TARGET_P99_MS,
        },
        "missions_per_minute": 60.0 * len(missions) / run["wall_s"],
        "mission_sim_time_s": float(sim.mean()),
        "mission_wall_s": float(wall.mean()),
        "mission_speed_x": float((sim / wall).mean()),
        "flight_wall_s": float(np.nanmean(flight)),
        "flight_speed_x": float(np.nanmean(sim / flight)),
        "target_speed_x": TARGET_SPEED_X,
        "mission_cpu_s": float(cpu.mean()),
        "cpu_s_per_sim_s": float((cpu / sim).mean()),
        "idle_machine_speed_x_bound": float((sim / (cpu / run["cpus"])).mean()),
        "flight_cpu_s": float(np.nanmean(flight_cpu)),
        "flight_cpu_ms_per_step": float(np.nanmean(flight_cpu / sim)) * 100.0,
        "idle_machine_flight_speed_x_bound": float(np.nanmean(sim / (flight_cpu / run["cpus"]))),
        "other_load_cpus": other / run["wall_s"],
        "run_wall_s": run["wall_s"],
    }


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    p.add_argument("--episodes", type=int, default=3, help="missions per pilot (default 3)")
    p.add_argument("--scenario", type=Path, default=REPO / "scenarios" / "strike.yaml")
    p.add_argument(
        "--models", type=Path, default=REPO / "models" / "tssac", help="trained policies (skipped if missing)"
    )
    add_json_option(p, "bridge")
    p.add_argument(
        "--full-telemetry",
        action="store_true",
        help="also fly with fly --full-telemetry (every stream on; fly's lockstep default streams only what the "
        "companions read)",
    )
    args = p.parse_args(argv)
    pilots: list[tuple[str, Path | None, tuple[str, ...]]] = [("guidance", None, ())]
    if args.full_telemetry:
        pilots.append(("guidance, full telemetry", None, ("--full-telemetry",)))
    if all((args.models / f"{r}.pt").is_file() for r in ("decoy", "detect", "strike")):
        pilots.append((str(args.models), args.models, ()))
    else:
        print(f"no trained policies in {args.models}: guidance only")
    figures = []
    for name, models, extra in pilots:
        with tempfile.TemporaryDirectory(prefix="bench-bridge-") as tmp:
            print(f"flying {args.episodes} x {args.scenario.name} in lockstep with {name} ...", flush=True)
            fig = summarise(name, run_fly(args.scenario, args.episodes, models, Path(tmp), extra))
        figures.append(fig)
        lat = fig["latency_ms"]
        print(
            f"  {name}: success {fig['success_rate']:.0%}, latency p50 {lat['p50']:.2f} ms p99 {lat['p99']:.2f} ms max "
            f"{lat['max']:.1f} ms "
            f"(target p99 < {TARGET_P99_MS:g})"
        )
        print(
            f"  {fig['missions_per_minute']:.2f} missions/min; a {fig['mission_sim_time_s']:.0f} s mission: "
            f"{fig['mission_wall_s']:.1f} s wall "
            f"({fig['mission_speed_x']:.1f}x real time), flight {fig['flight_wall_s']:.1f} s "
            f"({fig['flight_speed_x']:.1f}x; target {TARGET_SPEED_X:g}x)"
        )
        print(
            f"  CPU {fig['mission_cpu_s']:.1f} s per mission ({fig['cpu_s_per_sim_s'] * 1000:.0f} ms per simulated s); "
            f"other load on the machine {fig['other_load_cpus']:.2f} CPUs; bound on an idle machine "
            f"{fig['idle_machine_speed_x_bound']:.0f}x"
        )
        print(
            f"  flight alone: {fig['flight_cpu_s']:.1f} CPU s ({fig['flight_cpu_ms_per_step']:.2f} ms per 0.1 s step, "
            f"world and companions); "
            f"bound on an idle machine {fig['idle_machine_flight_speed_x_bound']:.0f}x"
        )
    out = {
        "scenario": str(args.scenario.relative_to(REPO) if args.scenario.is_relative_to(REPO) else args.scenario),
        "clock": "lockstep",
        "pilots": figures,
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "loadavg_after": os.getloadavg()},
    }
    write_figures(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
