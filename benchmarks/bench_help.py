"""Seconds of every command's ``--help`` (issue 42's target: < 1 s): wall time and the process's CPU time (user +
system), the best of a few fresh processes each. CPU time is the figure a busy machine does not inflate; the
wall time is printed beside it with the load average. tests/test_help_imports.py holds the cause (no torch,
gymnasium, Ray, matplotlib or filterpy before argparse) without a clock. Writes
the figures as JSON (``--json``, benchmarks/output.py).

    python benchmarks/bench_help.py [--runs 3]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # for benchmarks.output
from benchmarks.output import add_json_option, write_figures  # noqa: E402
from tssac_core.common.cli import command_description

ROOT = Path(__file__).resolve().parent.parent
COMMANDS = (
    "tssac_core.train",
    "tssac_core.evaluate",
    "tssac_core.experiments",
    "tssac_core.experiments.targets",
    "tssac_core.deploy.export",
    "mavlink_bridge.fly",
    "mavlink_bridge.companion",
    "sim_vehicles",
)


def one_run(module: str) -> tuple[float, float]:
    """(wall s, CPU s) of ``python -m module --help`` in a fresh process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", module, "--help"], check=True, capture_output=True, cwd=ROOT)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main() -> None:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    p.add_argument("--runs", type=int, default=3)
    add_json_option(p, "help")
    args = p.parse_args()
    rows = {}
    print(f"--help, best of {args.runs} fresh processes (1-minute load average {os.getloadavg()[0]:.1f}):")
    for module in COMMANDS:
        runs = [one_run(module) for _ in range(args.runs)]
        wall, cpu = min(r[0] for r in runs), min(r[1] for r in runs)
        rows[module] = {"wall_s": round(wall, 3), "cpu_s": round(cpu, 3)}
        print(f"  python -m {module:32s} wall {wall:5.2f} s   CPU {cpu:5.2f} s")
    write_figures(args.json, {"runs": args.runs, "load_avg_1m": os.getloadavg()[0], "commands": rows})


if __name__ == "__main__":
    main()
