"""``python -m tssac_core.train``: train the team, role by role (Algorithm 1).

Examples::

    python -m tssac_core.train --algo tssac --seed 0 --out runs/tssac-0
    python -m tssac_core.train --algo sac_lag --seed 1 --epochs 20 --out runs/sac_lag-1
    python -m tssac_core.train --out runs/tssac-0 --resume        # after a crash or kill -9
    python -m tssac_core.train --algo tssac --seeds 0,1,2 --out runs/tssac   # one job per seed: runs/tssac/seed<N>/
    python -m tssac_core.train --preset configs/safe.yaml --out runs/t --tensorboard runs/tb   # live curves

The run directory's contents: :mod:`tssac_core.train.rundir`. ``--tensorboard DIR`` also writes every epoch's
scalars as TensorBoard events (:mod:`tssac_core.train.tensorboard`; the ``tensorboard`` extra). Ctrl-C stops the
run and prints the command that continues it. torch and the training loop are imported after the arguments are
parsed, so ``--help`` and bad input answer at once.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import shlex
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from tssac_core.common.cli import EXIT_INTERRUPTED, UsageError, run, write_json
from tssac_core.parallel.ray_cluster import RayTarget
from tssac_core.sim.scenario import Role
from tssac_core.train.arguments import EXECUTORS, SeedJobs, parse_cli
from tssac_core.train.config import TrainConfig
from tssac_core.train.legacy import read_config
from tssac_core.train.wall_time import Ended, begin_invocation, record_invocation

logger = logging.getLogger("tssac_core.train")

SEEDS_FILE = "seeds.json"
"""``--seeds`` writes the list of its seeds here, in --out, so that ``--out DIR --resume`` continues them all."""


def console() -> int:
    """``tssac-train`` and ``python -m tssac_core.train``: :func:`main` with known errors as one line (exit 2)."""
    return run(main)


def main(argv: Sequence[str] | None = None) -> int:
    cfg, out, resume, quiet, jobs, tensorboard = parse_cli(argv)
    try:
        if jobs.seeds is not None or (resume and (out / SEEDS_FILE).is_file()):
            return train_seeds(cfg, jobs, out, resume, tensorboard)
        if jobs.executor != EXECUTORS[0]:
            raise UsageError(f"--executor {jobs.executor} runs the jobs of --seeds (one run trains here)")
        return train_one(cfg, out, resume, quiet, tensorboard)
    except KeyboardInterrupt:
        print(resume_hint(out), file=sys.stderr)
        return EXIT_INTERRUPTED


def resume_hint(out: Path) -> str:
    """What Ctrl-C prints: the exact command that continues the run in ``out`` (its config.json, or seeds.json,
    holds every other setting), or, when nothing was saved yet, that the same command starts it again."""
    if (out / "config.json").is_file() or (out / SEEDS_FILE).is_file():
        return f"interrupted; continue with: python -m tssac_core.train --out {shlex.quote(str(out))} --resume"
    return "interrupted before anything was saved; run the same command again to start"


def train_one(cfg: TrainConfig, out: Path, resume: bool, quiet: bool, tensorboard: Path | None) -> int:
    """One run (``--seed``): every role of the curriculum in turn, into ``out``."""
    import torch  # here, not above: --help and bad input answer without loading torch

    from tssac_core.reporting.progress import progress_bar
    from tssac_core.train.loop import train_role
    from tssac_core.train.rundir import MetricsRow, prepare_run, shipped, write_plots
    from tssac_core.train.tensorboard import EpochSink, open_sink

    cfg, scenario = prepare_run(cfg, out, resume)
    torch.set_num_threads(cfg.threads)
    total = len(cfg.roles) * cfg.epochs * cfg.steps_per_epoch
    start = time.perf_counter()
    begin_invocation(out)
    sink: EpochSink | None = open_sink(tensorboard) if tensorboard is not None else None

    def on_epoch(row: MetricsRow) -> None:
        record_invocation(out, time.perf_counter() - start, Ended.RUNNING)  # a kill now costs this epoch at most
        if sink is not None:
            sink.write(row)

    with (
        progress_bar(
            total=total, desc=f"{cfg.algo} seed {cfg.seed}", unit="step", disable=quiet, smoothing=0.05
        ) as bar,
        contextlib.closing(sink) if sink is not None else contextlib.nullcontext(),
    ):
        plotted = False  # the figures drawn after the last role trained here are the final ones
        for role_name in cfg.roles:
            role = Role(role_name)
            if shipped(out, role):
                logger.info("%s: already trained (%s)", role_name, out / f"{role_name}.pt")
                continue
            train_role(cfg, scenario, role, out, resume, bar, on_epoch=on_epoch)
            write_plots(out, scenario.cost_limit)
            plotted = True
    if not plotted:
        write_plots(out, scenario.cost_limit)
    wall_s = time.perf_counter() - start
    record_invocation(out, wall_s, Ended.FINISHED)
    print(f"trained {', '.join(cfg.roles)} with {cfg.algo} (seed {cfg.seed}) in {wall_s:.0f} s; results in {out}")
    return 0


def seed_dir(out: Path, seed: int) -> Path:
    return out / f"seed{seed}"


def board(tensorboard: Path | None, seed: int) -> Path | None:
    """A seed job's TensorBoard directory: its own subdirectory of the command's (none without one)."""
    return None if tensorboard is None else seed_dir(tensorboard, seed)


def saved_config(run_dir: Path) -> TrainConfig:
    """The TrainConfig in ``run_dir/config.json`` (UsageError naming the file if it cannot be read)."""
    return read_config(run_dir / "config.json", "--resume")


def train_seeds(cfg: TrainConfig, where: SeedJobs, out: Path, resume: bool, tensorboard: Path | None = None) -> int:
    """``--seeds``: one training job per seed (``out/seed<N>``, what ``--seed N --out out/seed<N>`` writes), all at
    once on the experiments' job executor (``--executor``: local processes or Ray tasks); on --resume the seeds
    of ``out/seeds.json``. With ``tensorboard``, seed N writes its events to ``tensorboard/seed<N>``. Exit 0 when
    every seed finished."""
    from tssac_core.train.jobs.executors import execute
    from tssac_core.train.jobs.job import AlgoEntry, Job
    from tssac_core.train.jobs.runner import Status, job_state

    seeds = where.seeds
    seeds_path = out / SEEDS_FILE
    if resume:
        try:
            saved = json.loads(seeds_path.read_text())["seeds"]
        except (OSError, ValueError, KeyError, TypeError):
            raise UsageError(f"--resume: {seeds_path} is missing or not readable (nothing to resume)") from None
        if seeds is not None and tuple(seeds) != tuple(saved):
            raise UsageError(f"--seeds {','.join(map(str, seeds))}: {out} holds seeds {','.join(map(str, saved))}")
        seeds = tuple(int(s) for s in saved)
    assert seeds is not None
    entry = AlgoEntry(cfg.algo, cfg)
    if resume:
        # Each seed's config.json wins, as for a single run: it is resumed as it was started.
        jobs = [
            Job(entry, saved_config(seed_dir(out, s)), seed_dir(out, s), tensorboard=board(tensorboard, s))
            for s in seeds
        ]
    else:
        if seeds_path.is_file() or any((seed_dir(out, s) / "config.json").is_file() for s in seeds):
            raise UsageError(f"{out} already holds a run; use --resume to continue it or choose another --out")
        jobs = [
            Job(entry, dataclasses.replace(cfg, seed=s), seed_dir(out, s), tensorboard=board(tensorboard, s))
            for s in seeds
        ]
        out.mkdir(parents=True, exist_ok=True)
        write_json(seeds_path, {"seeds": list(seeds)})
    states = [job_state(job) for job in jobs]
    conflicts = [s for s in states if s.status is Status.CONFLICT]
    if conflicts:
        raise UsageError(f"{conflicts[0].job.out}: {conflicts[0].detail}")
    launches = execute(states, where.executor, parallel=len(seeds), ray_target=RayTarget(where.address))
    failed = [launch.job.name for launch in launches if launch.returncode != 0]
    if failed:
        print(f"error: {', '.join(failed)} failed: see train.log in their directories", file=sys.stderr)
        return 1
    print(f"trained seeds {', '.join(map(str, seeds))} with {cfg.algo}; results in {out}/seed<N>")
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
