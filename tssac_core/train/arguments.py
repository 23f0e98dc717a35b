"""The training command's arguments: argv -> `TrainConfig` (flags over a preset), or ``--config FILE``: a
`TrainConfig` as JSON, the way the experiment grid's jobs and ``--seeds`` start a run (nothing turns a
`TrainConfig` back into flags)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tssac_core.common.cli import SEED_MAX, UsageError
from tssac_core.common.options import OptionError, add_flags, flag_name, flag_values
from tssac_core.train.config import TrainConfig
from tssac_core.train.jobs.executors import EXECUTORS
from tssac_core.train.legacy import read_config
from tssac_core.train.preset import load_preset

DESCRIPTION = "python -m tssac_core.train: train the team, role by role (Algorithm 1)."


@dataclass(frozen=True)
class SeedJobs:
    """``--seeds`` and where its jobs run."""

    seeds: tuple[int, ...] | None
    """None: one run (``--seed``), or on --resume the seeds the run directory lists."""
    executor: str = EXECUTORS[0]
    """An executor of tssac_core.train.jobs.executors: local processes or Ray tasks."""
    address: str | None = None
    """``--executor ray``: an existing Ray cluster (None: a Ray started inside the command)."""


def parse_args(argv: Sequence[str] | None) -> tuple[TrainConfig, Path, bool, bool]:
    """The run's TrainConfig, --out, --resume and --no-progress (see `parse_cli` for --seeds)."""
    cfg, out, resume, quiet, _, _ = parse_cli(argv)
    return cfg, out, resume, quiet


def parse_seeds(text: str) -> tuple[int, ...]:
    try:
        seeds = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise UsageError(f"--seeds: {text!r} is not a comma-separated list of integers") from None
    if not seeds or len(set(seeds)) != len(seeds):
        raise UsageError(f"--seeds: give one or more distinct seeds, got {text!r}")
    for seed in seeds:
        if not 0 <= seed <= SEED_MAX:
            raise UsageError(f"--seeds: invalid seed {seed}: a whole number from 0 to {SEED_MAX}")
    return seeds


def parse_cli(argv: Sequence[str] | None) -> tuple[TrainConfig, Path, bool, bool, SeedJobs, Path | None]:
    """The run's TrainConfig, --out, --resume, --no-progress, --seeds (and where they run), and --tensorboard. The
    TrainConfig's flags are its fields' options (tssac_core.common.options), over a preset's values if one is named."""
    first = argparse.ArgumentParser(add_help=False)
    first.add_argument("--preset", type=Path)
    first.add_argument("--config", type=Path)
    known = first.parse_known_args(argv)[0]
    if known.config is not None:
        return parse_job(argv)
    preset = load_preset(known.preset) if known.preset is not None else None
    p = argparse.ArgumentParser(prog="python -m tssac_core.train", description=DESCRIPTION)
    add_command_flags(p)
    add_flags(p, TrainConfig, preset.values if preset is not None else None)
    a = p.parse_args(argv)
    overrides: dict[str, Any] = dict(preset.learner_settings(a.algo)) if preset is not None else {}
    for item in a.set:
        key, _, value = item.partition("=")
        try:
            overrides[key] = json.loads(value)
        except json.JSONDecodeError:
            overrides[key] = value  # a word, e.g. multiplier_signal=q_c; SacConfig checks it
    try:
        cfg = TrainConfig(**flag_values(a, TrainConfig), learner=overrides)
    except OptionError as exc:
        flag = flag_name(exc.field)
        given = any(arg == flag or arg.startswith(f"{flag}=") for arg in (sys.argv[1:] if argv is None else argv))
        if preset is not None and exc.field in preset.values and not given:
            raise UsageError(f"{preset.source}: {exc.field}: {exc.problem}") from None  # the value is the preset's
        raise UsageError(f"{flag}: {exc.problem}") from None
    if a.address is not None and a.executor != EXECUTORS[1]:
        raise UsageError("--address is for --executor ray")
    jobs = SeedJobs(parse_seeds(a.seeds) if a.seeds is not None else None, a.executor, a.address)
    if a.tensorboard is not None:
        require_tensorboard()
    return cfg, a.out, a.resume, a.no_progress, jobs, a.tensorboard


def add_command_flags(p: argparse.ArgumentParser) -> None:
    """The command's flags that are not TrainConfig fields: the recipe, the run directory, the seeds' jobs, --set."""
    p.add_argument(
        "--preset",
        type=Path,
        metavar="FILE",
        help="a recipe file (configs/paper.yaml, configs/safe.yaml): its "
        "settings are the defaults, the flags given here override them (tssac_core.train.preset)",
    )
    p.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help="a whole TrainConfig as JSON (what a run's config.json holds): train exactly that, into --out; "
        "only --out, --no-progress and --tensorboard go with it (the experiment grid starts its jobs so)",
    )
    p.add_argument(
        "--seeds",
        help="train these seeds (e.g. 0,1,2), one job per seed (tssac_core.train.jobs.executors), into "
        "--out/seed<N>/ (replaces --seed)",
    )
    p.add_argument(
        "--executor",
        choices=EXECUTORS,
        default=EXECUTORS[0],
        help="--seeds: run the seeds' jobs as processes here (local, default) or as Ray tasks (ray: a Ray started "
        "inside the command, or --address)",
    )
    p.add_argument("--address", metavar="HOST:PORT", help="--executor ray: an existing Ray cluster (docs/ray.md)")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help=(
            "override a learner setting (SacConfig or OnPolicyConfig field), e.g. --set lr=3e-4 or --set "
            "multiplier_signal=q_c"
        ),
    )
    p.add_argument(
        "--out", type=Path, required=True, help="run directory (config, metrics, checkpoints, plots, resume state)"
    )
    p.add_argument("--resume", action="store_true", help="continue the run in --out (its config.json wins)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--tensorboard",
        type=Path,
        metavar="DIR",
        help="also write every epoch's scalars (return, cost, multiplier, losses, validation) as TensorBoard events "
        "in DIR (the tensorboard extra: pip install -e '.[tensorboard]'); with --seeds, DIR/seed<N>",
    )


def parse_job(argv: Sequence[str] | None) -> tuple[TrainConfig, Path, bool, bool, SeedJobs, Path | None]:
    """``--config FILE --out DIR [--no-progress] [--tensorboard DIR]``: the run of a TrainConfig written as JSON
    (`tssac_core.train.config.config_record`); any other flag is refused."""
    p = argparse.ArgumentParser(prog="python -m tssac_core.train --config FILE", description=DESCRIPTION)
    p.add_argument("--config", type=Path, required=True, metavar="FILE", help="a TrainConfig as JSON")
    p.add_argument("--out", type=Path, required=True, help="run directory")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--tensorboard", type=Path, metavar="DIR", help="also write TensorBoard events in DIR")
    a = p.parse_args(argv)
    if a.tensorboard is not None:
        require_tensorboard()
    return read_config(a.config, "--config"), a.out, False, a.no_progress, SeedJobs(None), a.tensorboard


def require_tensorboard() -> None:
    """UsageError (one line) when ``--tensorboard`` is asked for but its optional package is not installed."""
    import importlib.util

    if importlib.util.find_spec("tensorboard") is None:
        raise UsageError("--tensorboard needs the tensorboard package: pip install -e '.[tensorboard]'")
