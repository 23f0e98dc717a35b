"""The training command's arguments: argv -> `TrainConfig` (flags over a preset), or ``--config FILE``: a
`TrainConfig` as JSON, the way the experiment grid's jobs and ``--seeds`` start a run (nothing turns a
`TrainConfig` back into flags)."""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tssac_core.common.cli import SEED_MAX, UsageError, seed_arg
from tssac_core.common.errors import MAX_ACTION_REPEAT
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.scenario import ROLES
from tssac_core.train.algorithms import ALGORITHMS, Algo, Selection
from tssac_core.train.config import DEFAULT_SCENARIO, TrainConfig
from tssac_core.train.legacy import read_config
from tssac_core.train.preset import load_preset

DESCRIPTION = "python -m tssac_core.train: train the team, role by role (Algorithm 1)."
EXECUTORS = ("local", "ray")
"""Where ``--seeds`` runs its jobs: tssac_core.experiments.executors.EXECUTORS (not imported: the experiments import
this module; tests/test_ray.py holds the two equal)."""


@dataclass(frozen=True)
class SeedJobs:
    """``--seeds`` and where its jobs run."""

    seeds: tuple[int, ...] | None
    """None: one run (``--seed``), or on --resume the seeds the run directory lists."""
    executor: str = EXECUTORS[0]
    """An executor of tssac_core.experiments.executors: local processes or Ray tasks."""
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
    """The run's TrainConfig, --out, --resume, --no-progress, --seeds (and where they run), and --tensorboard."""
    first = argparse.ArgumentParser(add_help=False)
    first.add_argument("--preset", type=Path)
    first.add_argument("--config", type=Path)
    known = first.parse_known_args(argv)[0]
    if known.config is not None:
        return parse_job(argv)
    preset_path = known.preset
    preset = load_preset(preset_path) if preset_path is not None else None
    p = argparse.ArgumentParser(prog="python -m tssac_core.train", description=DESCRIPTION)
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
        "--algo",
        choices=list(ALGORITHMS),
        type=Algo,
        default=Algo.TSSAC,
        help="learner (default tssac: SAC-Lagrangian, damped multiplier, transfer)",
    )
    p.add_argument(
        "--scenario", type=Path, default=DEFAULT_SCENARIO, help="scenario file (default scenarios/random.yaml)"
    )
    p.add_argument("--seed", type=seed_arg, default=0, help="seed of networks, layouts and exploration")
    p.add_argument(
        "--seeds",
        help="train these seeds (e.g. 0,1,2), one job per seed (tssac_core.experiments.executors), into "
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
    p.add_argument("--epochs", type=int, default=50, help="epochs per role (Table 3: 50)")
    p.add_argument("--steps-per-epoch", type=int, default=4000, help="learner decisions per epoch (Table 3: 4000)")
    p.add_argument("--roles", default="decoy,detect,strike", help="comma-separated, in curriculum order")
    p.add_argument("--envs", type=int, default=4, help="parallel worlds (default 4)")
    p.add_argument(
        "--update-every", type=int, default=1, help="one gradient update per this many decisions (default 1)"
    )
    p.add_argument(
        "--start-steps",
        type=int,
        default=4000,
        help="uniform random actions for this many decisions first (from-scratch roles)",
    )
    p.add_argument(
        "--update-after", type=int, default=1000, help="no updates before the buffer holds this many transitions"
    )
    p.add_argument(
        "--action-repeat", type=int, default=1, help="hold each action for this many 0.1 s world steps (default 1)"
    )
    p.add_argument(
        "--observation",
        choices=[m.value for m in ObservationMode],
        default="route",
        help="observation (default route = extended + the way around the radars; paper = eq. 7)",
    )
    p.add_argument("--penalty", type=float, default=0.0, help="sac_penalty: reward r + penalty * c (e.g. -10)")
    p.add_argument(
        "--route-margin-km",
        type=float,
        default=3.0,
        help="reward and route observation: the way to the zone keeps this far from the radars (default 3)",
    )
    p.add_argument(
        "--cost-margin-km",
        type=float,
        default=1.0,
        help="the learner's cost counts steps within this distance of a radar (default 1; 0: eq. 11 exactly)",
    )
    p.add_argument(
        "--airframe-response",
        type=Path,
        default=None,
        metavar="FILE",
        help="train on airframes varied per episode within this fitted response's spans (turn lag, achievable "
        "acceleration; e.g. sim_vehicles/dynamics/airframes/f16.response.yaml; default: eq. 5-6 exactly)",
    )
    p.add_argument(
        "--vary-wind-m-s",
        type=float,
        default=0.0,
        help="with --airframe-response: a constant wind per episode, up to this speed (m/s; default 0)",
    )
    p.add_argument(
        "--vary-turn-noise-deg-s",
        type=float,
        default=0.0,
        help="with --airframe-response: turbulence, a heading-rate disturbance of this standard deviation (default 0)",
    )
    p.add_argument(
        "--hard-layouts",
        type=float,
        default=0.0,
        metavar="FRACTION",
        help="draw this share of training episodes from hard layouts only (default 0: the scenario's own draw)",
    )
    p.add_argument(
        "--hard-detour-km",
        type=float,
        default=20.0,
        help="hard layout: some UAV's way around the radars is this much longer than the straight line (default 20)",
    )
    p.add_argument(
        "--validation-episodes",
        type=int,
        default=30,
        help="held-out missions flown after every epoch to pick the shipped one (0: ship the last epoch)",
    )
    p.add_argument(
        "--selection",
        choices=list(Selection),
        type=Selection,
        help="which validated epoch a role ships: the best mission success among the "
        "epochs within the cost limit (within_limit: default of tssac, sac_lag, ppo_lag, cpo), or whatever the cost "
        "(success: default of sac, sac_penalty, ppo), or tail: screen every epoch on the upper bound of its cost and "
        "its "
        "within-C fraction, and choose among the best three on more missions (tssac_core.train.validation)",
    )
    p.add_argument(
        "--init-from",
        type=Path,
        help="initialise the learner of every trained role from this role checkpoint (fine-tuning)",
    )
    p.add_argument(
        "--teammates",
        type=Path,
        help="directory whose trained earlier roles fly beside (and, for tssac, transfer to) "
        "the trained roles, e.g. models/tssac with --roles strike (default: --out itself)",
    )
    p.add_argument(
        "--stop-at-task-success",
        type=float,
        default=0.0,
        metavar="FRACTION",
        help=(
            "end a role after the first epoch whose task success in training reaches this (e.g. 0.9; default 0: never)"
        ),
    )
    p.add_argument(
        "--threads",
        type=int,
        default=1,
        help="torch threads (default 1, whatever the machine: runs beside each other want a core each)",
    )
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
    if preset is not None:
        p.set_defaults(**preset.argparse_defaults())
    a = p.parse_args(argv)
    roles = tuple(r.strip() for r in a.roles.split(",") if r.strip())
    for r in roles:
        if r not in [x.value for x in ROLES]:
            raise UsageError(f"--roles: unknown role {r!r}")
    if list(roles) != [x.value for x in ROLES if x.value in roles]:
        raise UsageError("--roles must follow the curriculum order decoy, detect, strike")
    if a.action_repeat > MAX_ACTION_REPEAT:
        raise UsageError(f"--action-repeat must be at most {MAX_ACTION_REPEAT}, got {a.action_repeat}")
    if min(a.epochs, a.steps_per_epoch, a.envs, a.update_every, a.action_repeat) <= 0:
        raise UsageError("--epochs, --steps-per-epoch, --envs, --update-every and --action-repeat must be positive")
    if min(a.validation_episodes, a.route_margin_km, a.cost_margin_km) < 0:
        raise UsageError("--validation-episodes, --route-margin-km and --cost-margin-km must be >= 0")
    if not (0.0 <= a.hard_layouts <= 1.0 and a.hard_detour_km >= 0):
        raise UsageError("--hard-layouts must be a fraction in [0, 1] and --hard-detour-km >= 0")
    if a.airframe_response is None and (a.vary_wind_m_s or a.vary_turn_noise_deg_s):
        raise UsageError("--vary-wind-m-s and --vary-turn-noise-deg-s vary the airframes of --airframe-response")
    if not (0.0 <= a.vary_wind_m_s <= 50.0 and 0.0 <= a.vary_turn_noise_deg_s <= 90.0):
        raise UsageError("--vary-wind-m-s must be in [0, 50] and --vary-turn-noise-deg-s in [0, 90]")
    if not 0.0 <= a.stop_at_task_success <= 1.0:
        raise UsageError(f"--stop-at-task-success must be a fraction in [0, 1], got {a.stop_at_task_success:g}")
    overrides: dict[str, Any] = dict(preset.learner_settings(a.algo)) if preset is not None else {}
    for item in a.set:
        key, _, value = item.partition("=")
        try:
            overrides[key] = json.loads(value)
        except json.JSONDecodeError:
            overrides[key] = value  # a word, e.g. multiplier_signal=q_c; SacConfig checks it
    cfg = TrainConfig(
        algo=a.algo,
        scenario=str(a.scenario),
        seed=a.seed,
        epochs=a.epochs,
        steps_per_epoch=a.steps_per_epoch,
        roles=roles,
        envs=a.envs,
        update_every=a.update_every,
        start_steps=a.start_steps,
        update_after=a.update_after,
        observation=a.observation,
        action_repeat=a.action_repeat,
        penalty=a.penalty,
        threads=a.threads,
        learner=overrides,
        validation_episodes=a.validation_episodes,
        route_margin_km=a.route_margin_km,
        cost_margin_km=a.cost_margin_km,
        hard_layouts=a.hard_layouts,
        hard_detour_km=a.hard_detour_km,
        init_from=str(a.init_from) if a.init_from else "",
        teammates=str(a.teammates) if a.teammates else "",
        stop_at_task_success=a.stop_at_task_success,
        airframe_response=str(a.airframe_response) if a.airframe_response else "",
        vary_wind_m_s=a.vary_wind_m_s,
        vary_turn_noise_deg_s=a.vary_turn_noise_deg_s,
        selection=a.selection,
    )
    if a.address is not None and a.executor != EXECUTORS[1]:
        raise UsageError("--address is for --executor ray")
    jobs = SeedJobs(parse_seeds(a.seeds) if a.seeds is not None else None, a.executor, a.address)
    if a.tensorboard is not None:
        require_tensorboard()
    return cfg, a.out, a.resume, a.no_progress, jobs, a.tensorboard


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
