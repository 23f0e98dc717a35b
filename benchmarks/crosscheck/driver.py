"""The cross-check's command (benchmarks/crosscheck_omnisafe.py), in the project's environment: for every
(implementation, algorithm, seed) not yet in the results file, train (ours with ``python -m tssac_core.train``,
OmniSafe's through benchmarks.crosscheck.omnisafe_side with OmniSafe's python), fly the evaluation layouts, write
the row; ``--report`` pools the seeds into a markdown table.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from benchmarks.crosscheck.actor_file import ActorFileError
from benchmarks.crosscheck.evaluation import detect_pilot, fly_detect
from benchmarks.crosscheck.rows import RowsError, RowStore, make_row, pool, setting, table
from benchmarks.crosscheck.settings import (
    ALGOS,
    EVAL_EPISODES,
    EVAL_SEED,
    IMPLS,
    PRESET,
    ROOT,
    SCENARIO,
    Budget,
    Job,
    SettingsError,
    Shared,
    omnisafe_cfgs,
    omnisafe_command,
    ours_command,
    parse_override,
    shared_settings,
)
from benchmarks.omnisafe_env import location, python_of
from benchmarks.output import default_json
from tssac_core.common.cli import UsageError, command_description
from tssac_core.sim.scenario import load
from tssac_core.train.config import TrainConfig
from tssac_core.train.wall_time import Ended, read_invocations

DEFAULT_ROWS = default_json("crosscheck_omnisafe")  # the committed rows: --rows benchmarks/results/...
DEFAULT_OMNISAFE_PYTHON = str(python_of(location()))  # benchmarks/omnisafe_env.py's environment


def words(text: str, allowed: Sequence[str], what: str) -> list[str]:
    items = [w.strip() for w in text.split(",") if w.strip()]
    bad = [w for w in items if w not in allowed]
    if bad or not items:
        raise UsageError(f"{what}: expected a comma-separated subset of {','.join(allowed)}, got {text!r}")
    return items


def seeds_of(text: str) -> list[int]:
    try:
        seeds = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise UsageError(f"--seeds: expected integers such as 0,1,2, got {text!r}") from None
    if not seeds or min(seeds) < 0 or len(set(seeds)) != len(seeds):
        raise UsageError(f"--seeds: expected distinct integers >= 0, got {text!r}")
    return seeds


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="benchmarks/crosscheck_omnisafe.py", description=command_description(__doc__))
    p.add_argument("--report", action="store_true", help="pool the rows' seeds and print/write the markdown table")
    p.add_argument("--rows", type=Path, default=DEFAULT_ROWS, help="results file, one row per (impl, algo, seed)")
    p.add_argument("--report-out", type=Path, help="--report: the markdown file (default: --rows with .md)")
    p.add_argument("--impls", default=",".join(IMPLS), help="ours,omnisafe (default both)")
    p.add_argument("--algos", default=",".join(ALGOS), help="cpo,ppo_lag,sac_lag (default all)")
    p.add_argument("--seeds", default="0,1,2", help="training seeds (default 0,1,2)")
    p.add_argument("--epochs", type=int, default=50, help="epochs (default 50, Table 3)")
    p.add_argument("--steps-per-epoch", type=int, default=4000, help="decisions of 1 s per epoch (default 4000)")
    p.add_argument("--episodes", type=int, default=EVAL_EPISODES, help=f"evaluation layouts (default {EVAL_EPISODES})")
    p.add_argument(
        "--eval-seed", type=int, default=EVAL_SEED, help=f"mission k flies layout seed this + k (default {EVAL_SEED})"
    )
    p.add_argument(
        "--work", type=Path, default=ROOT / "runs" / "crosscheck", help="run directories (default runs/crosscheck)"
    )
    p.add_argument("--omnisafe-python", default=DEFAULT_OMNISAFE_PYTHON, help="OmniSafe's python")
    p.add_argument(
        "--omnisafe-set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override an OmniSafe setting for every OmniSafe run, dotted (e.g. algo_cfgs.update_iters=10)",
    )
    return p.parse_args(argv)


def child_env() -> dict[str, str]:
    """The environment of the training commands: this checkout's packages first."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    return env


@dataclass(frozen=True)
class Spent:
    """What one training command spent: wall seconds, and CPU seconds (user + system) of it and its children,
    imports and start-up included (the CPU figure is the one to budget with on a shared machine)."""

    wall_s: float
    cpu_s: float


def run_logged(cmd: list[str], log: Path, what: str) -> Spent:
    """Run ``cmd`` from the repository root with its output appended to ``log``."""
    log.parent.mkdir(parents=True, exist_ok=True)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    with log.open("a") as fh:
        fh.write(f"$ {' '.join(cmd)}\n")
        fh.flush()
        rc = subprocess.run(cmd, cwd=ROOT, env=child_env(), stdout=fh, stderr=subprocess.STDOUT).returncode
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if rc != 0:
        raise UsageError(f"{what}: training failed (exit {rc}); see {log}")
    return Spent(wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime))


def train_ours(job: Job, budget: Budget, run_dir: Path) -> tuple[list[list[str]], float, Spent | None]:
    """Train (or finish) our run; (commands, learner wall s, what this invocation's command spent, if it ran)."""
    commands: list[list[str]] = []
    process: Spent | None = None
    invocations = read_invocations(run_dir)
    if not any(i.ended is Ended.FINISHED for i in invocations):
        cmd = ours_command(sys.executable, job, budget, run_dir, resume=(run_dir / "config.json").is_file())
        process = run_logged(cmd, run_dir / "crosscheck-train.log", job.name)
        commands.append(cmd)
    learner = float(sum(i.seconds for i in read_invocations(run_dir)))
    if not commands:
        commands.append(ours_command(sys.executable, job, budget, run_dir))
    return commands, learner, process


def train_omnisafe(
    job: Job, budget: Budget, run_dir: Path, shared: Shared, python: str, overrides: dict[str, Any]
) -> tuple[list[list[str]], float, Spent | None, dict[str, Any]]:
    """Train OmniSafe's run unless its train.json is there; (commands, learner wall s, what its command spent if
    it ran, cfgs)."""
    cfgs_file = run_dir / "omnisafe_cfgs.json"
    cfgs = {
        "algo": ALGOS[job.algo],
        **omnisafe_cfgs(job.algo, budget, job.seed, shared, run_dir / "omnisafe", overrides),
    }
    cmd = omnisafe_command(python, cfgs_file, run_dir)
    process: Spent | None = None
    if not (run_dir / "train.json").is_file():
        shutil.rmtree(run_dir / "omnisafe", ignore_errors=True)  # a killed run's logs: start again
        run_dir.mkdir(parents=True, exist_ok=True)
        cfgs_file.write_text(json.dumps(cfgs, indent=2) + "\n")
        process = run_logged(cmd, run_dir / "crosscheck-train.log", job.name)
    learner = float(json.loads((run_dir / "train.json").read_text())["train_wall_s"])
    return [cmd], learner, process, cfgs


def run_jobs(args: argparse.Namespace) -> int:
    budget = Budget(args.epochs, args.steps_per_epoch)
    if args.episodes < 1:
        raise UsageError(f"--episodes must be >= 1, got {args.episodes}")
    impls = words(args.impls, IMPLS, "--impls")
    algos = words(args.algos, list(ALGOS), "--algos")
    seeds = seeds_of(args.seeds)
    overrides = dict(parse_override(o) for o in args.omnisafe_set)
    if "omnisafe" in impls and not Path(args.omnisafe_python).is_file():
        raise UsageError(
            f"--omnisafe-python: no such file {args.omnisafe_python} (python benchmarks/omnisafe_env.py builds it)"
        )
    scenario = load(SCENARIO)
    shared = shared_settings(yaml.safe_load(PRESET.read_text()), scenario.cost_limit, TrainConfig.cost_margin_km)
    the_setting = setting(budget, args.episodes, args.eval_seed, scenario.cost_limit)
    store = RowStore(args.rows)
    for seed in seeds:
        for algo in algos:
            for impl in impls:
                job = Job(impl, algo, seed)
                if store.done(job, the_setting):
                    print(f"{job.name}: in {args.rows}, skipped")
                    continue
                run_dir = args.work / job.name
                extra: dict[str, Any] = {}
                if impl == "ours":
                    commands, learner, process = train_ours(job, budget, run_dir)
                else:
                    commands, learner, process, cfgs = train_omnisafe(
                        job, budget, run_dir, shared, args.omnisafe_python, overrides
                    )
                    extra["omnisafe_custom_cfgs"] = cfgs
                start = time.perf_counter()
                missions = fly_detect(detect_pilot(impl, run_dir), args.episodes, args.eval_seed)
                eval_wall = time.perf_counter() - start
                row = make_row(
                    job, the_setting, missions.task_done, missions.cost, learner, eval_wall, commands, str(run_dir)
                )
                decisions = budget.decisions
                row["process_wall_s"] = None if process is None else round(process.wall_s, 2)
                row["process_cpu_s"] = None if process is None else round(process.cpu_s, 2)
                row["cpu_ms_per_decision"] = None if process is None else round(1000 * process.cpu_s / decisions, 3)
                row.update(extra)
                store.add(row)
                print(
                    f"{job.name}: detect task {100 * row['task_success']['value']:.1f}%, mean cost "
                    f"{row['mean_cost']['value']:.2f}, within C {100 * row['within_c']['value']:.1f}%; trained in "
                    f"{learner:.0f} s ({row['ms_per_decision']:.1f} ms/decision; "
                    f"CPU {row['cpu_ms_per_decision']} ms/decision), "
                    f"evaluated in {eval_wall:.0f} s"
                )
    return 0


def report(args: argparse.Namespace) -> int:
    if not args.rows.is_file():
        raise UsageError(f"--rows: no such file {args.rows}")
    text = table(pool(RowStore(args.rows).rows))
    out = args.report_out or args.rows.with_suffix(".md")
    out.write_text(text)
    print(text + f"\nwrote {out}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        return report(args) if args.report else run_jobs(args)
    except (SettingsError, RowsError, ActorFileError) as exc:
        raise UsageError(str(exc)) from None
