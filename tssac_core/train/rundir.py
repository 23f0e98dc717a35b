"""A run directory: ``config.json``, ``metrics.csv``, the role checkpoints, the plots, and ``resume/``.

Output in ``--out``: ``config.json``, ``metrics.csv`` (one row per role and epoch), one checkpoint per role
(``decoy.pt``, ``detect.pt``, ``strike.pt``) and its exported actor (``<role>.npz``), ``SHA256SUMS`` (the
SHA-256 of config.json and each finished role's two files, updated as each role ships: tssac_core.deploy.manifest),
``fig7_return_cost.png`` and ``fig8_multiplier.png``, ``wall_time.json`` (the wall time of each invocation, brought
up to date after every epoch: :mod:`tssac_core.train.wall_time`), and ``resume/`` (the last completed
epoch: learner, replay buffer, worlds and random states), from which ``--resume`` continues, losing at most the
epoch that was running.
"""

from __future__ import annotations

import csv
import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path

import torch

from tssac_core.algos.networks import SquashedGaussianActor
from tssac_core.algos.onpolicy.ppo import CpoState, PpoState
from tssac_core.algos.sac_lagrangian import SacState, UpdateStats
from tssac_core.common.cli import UsageError, write_json
from tssac_core.common.errors import CheckpointError
from tssac_core.deploy.manifest import CONFIG, check_model_file, check_recorded, read_manifest, record, warn_once
from tssac_core.deploy.numpy_actor import NumpyPolicy
from tssac_core.deploy.policy import (
    CheckpointInfo,
    checkpoint_info,
    learner_state,
    package_versions,
    read_checkpoint,
    save_role_checkpoint,
)
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.scenario import ROLES, Role, Scenario, load_for_batched_world
from tssac_core.train.config import (
    TrainConfig,
    check_learner_settings,
    config_record,
    sac_config,
    with_recorded_defaults,
)
from tssac_core.train.legacy import read_config
from tssac_core.train.resume import read_resume_state

logger = logging.getLogger("tssac_core.train")


def role_checkpoint(cfg: TrainConfig, out: Path, role: Role) -> Path:
    """Where a trained earlier role is: in this run if it trains that role (or has no ``teammates``), else in
    ``teammates``."""
    if cfg.teammates and role.value not in cfg.roles:
        return Path(cfg.teammates) / f"{role.value}.pt"
    return out / f"{role.value}.pt"


def save_trained_role(
    path: Path,
    cfg: TrainConfig,
    scenario: Scenario,
    role: Role,
    hidden_sizes: tuple[int, ...],
    actor_state: dict[str, torch.Tensor],
    learner_state: SacState | PpoState | CpoState,
    env_steps: int,
    updates: int,
    epoch: int,
) -> None:
    """Write a role checkpoint: the deployable actor, what it fits, and the learner's state for transfer."""
    mode = ObservationMode(cfg.observation)
    info = CheckpointInfo(
        role=role,
        algo=cfg.algo,
        observation_mode=mode,
        obs_dim=mode.size,
        act_dim=2,
        hidden_sizes=hidden_sizes,
        scenario_digest=scenario.digest(),
        versions=package_versions(),
        metrics={"epoch": epoch, "env_steps": env_steps, "updates": updates},
        action_repeat=cfg.action_repeat,
    )
    save_role_checkpoint(path, info, actor_state, learner_state)


def role_position(cfg: TrainConfig, role: Role) -> int:
    return list(cfg.roles).index(role.value)


METRIC_FIELDS = [
    "role",
    "epoch",
    "env_steps",
    "episodes",
    "return",
    "cost",
    "task_success",
    "mission_success",
    *[f.name for f in dataclasses.fields(UpdateStats)],
    "env_steps_per_s",
    "updates_per_s",
    "updates",
    "val_mission_success",
    "val_task_success",
    "val_cost",
    "best_epoch",
    "hazard_cost",
    "val_cost_high",
    "val_within_limit",
    "val_cvar95_cost",
    "val_max_cost",
]


@dataclass(frozen=True)
class MetricsRow:
    """One epoch's row of ``metrics.csv``: the role and the epoch's figures by column (counts are ints).

    The columns the file has are :data:`METRIC_FIELDS`; :meth:`csv_row` is what it gets."""

    role: Role
    figures: dict[str, float]
    """Column -> value: the epoch and its counts, the episodes' means, the update statistics, the learner's own
    columns and the validation's."""

    def csv_row(self) -> dict[str, str | float]:
        return {"role": self.role.value, **self.figures}


def append_metrics(path: Path, row: MetricsRow) -> None:
    """Append one epoch's row; a resumed run keeps the columns its file was started with."""
    new = not path.is_file()
    fields = METRIC_FIELDS
    if not new:
        with path.open(newline="") as fh:
            fields = next(csv.reader(fh), METRIC_FIELDS)
    with path.open("a", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        if new:
            writer.writeheader()
        writer.writerow(row.csv_row())


def truncate_metrics(path: Path, keep: set[tuple[str, int]]) -> None:
    """On resume, drop rows of epochs that were not checkpointed (they will be run again)."""
    if not path.is_file():
        return
    with path.open() as fh:
        rows = [r for r in csv.DictReader(fh) if (r["role"], int(r["epoch"])) in keep]
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=METRIC_FIELDS)
        writer.writeheader()
        writer.writerows(rows)


def shipped(out: Path, role: Role | str) -> bool:
    """``role`` is finished: its ``<role>.pt`` loads as a role checkpoint, its ``<role>.npz`` export too if there
    is one, and the run's manifest (if it has one) lists both as they are. A file that exists but does not load or
    match is reported (one line) and the role is trained again (from its resume state): a kill between writing the
    files and recording them lands here."""
    name = Role(role).value
    pt, npz = out / f"{name}.pt", out / f"{name}.npz"
    if not pt.is_file():
        return False
    try:
        checkpoint_info(read_checkpoint(pt), pt)
        if npz.is_file():
            NumpyPolicy.load(npz)
        check_recorded(out, [p.name for p in (pt, npz) if p.is_file()])
    except CheckpointError as exc:
        logger.warning("%s; training %s again from its resume state", exc, name)
        return False
    return True


def record_run(cfg: TrainConfig, out: Path) -> None:
    """Record ``config.json`` in the run's manifest (the file this run goes by); a run begun before manifests
    existed also gets its finished roles' files, so that its manifest lists everything its loaders read."""
    names = [CONFIG]
    if read_manifest(out) is None:
        finished = [role for role in cfg.roles if shipped(out, role)]
        names += [name for role in finished for name in (f"{role}.pt", f"{role}.npz") if (out / name).is_file()]
    record(out, names)


def check_inputs(cfg: TrainConfig, out: Path) -> None:
    """The model files this run reads from elsewhere (``teammates``, ``init_from``) match their manifests
    (CheckpointError, one line, before any work otherwise)."""
    paths = {role_checkpoint(cfg, out, earlier) for role in map(Role, cfg.roles) for earlier in ROLES[: role.index]}
    paths = {p for p in paths if p.parent != out and p.is_file()}
    if cfg.init_from:
        paths |= {init_checkpoint(cfg, Role(role)) for role in cfg.roles}
    for path in sorted(paths):
        warn_once(check_model_file(path))


def completed_epochs(out: Path, role: str) -> int:
    """Epochs of ``role`` that a resume can skip: all if it shipped (`shipped`), else the resume state's."""
    if shipped(out, role):
        return -1
    state = read_resume_state(out, role, warn=False)  # the training loop warns once when it reads it
    return state.epoch if state is not None else 0


def prepare_run(cfg: TrainConfig, out: Path, resume: bool) -> tuple[TrainConfig, Scenario]:
    """Check the run and set up ``out``: config.json written (or, on --resume, read: it wins), earlier roles
    present, metrics of epochs that were not checkpointed dropped. Returns the run's config and scenario."""
    config_path = out / "config.json"
    if resume:
        if not config_path.is_file():
            raise UsageError(f"--resume: {config_path} not found (nothing to resume)")
        cfg = read_config(config_path, "--resume")
    elif config_path.is_file():
        raise UsageError(f"{out} already holds a run; use --resume to continue it or choose another --out")
    else:
        cfg = with_recorded_defaults(cfg)
    scenario = load_for_batched_world(cfg.scenario)
    check_learner_settings(cfg, scenario)
    if cfg.init_from:
        check_init_from(cfg, scenario)
    for role_name in cfg.roles:
        role = Role(role_name)
        for earlier in ROLES[: role.index]:
            path = role_checkpoint(cfg, out, earlier)
            if earlier.value not in cfg.roles and not path.is_file():
                raise UsageError(f"training {role.value} needs {path} (train {earlier.value} first)")
    check_inputs(cfg, out)
    out.mkdir(parents=True, exist_ok=True)
    if not resume:
        write_json(config_path, config_record(cfg))
    record_run(cfg, out)
    keep = set()
    for role_name in cfg.roles:
        done = completed_epochs(out, role_name)
        keep |= {(role_name, e) for e in range(1, (cfg.epochs if done < 0 else done) + 1)}
    truncate_metrics(out / "metrics.csv", keep)
    return cfg, scenario


def write_plots(out: Path, cost_limit: float) -> None:
    from tssac_core.reporting.plots import plot_training

    plot_training(out / "metrics.csv", out, cost_limit)


def init_checkpoint(cfg: TrainConfig, role: Role) -> Path:
    """The checkpoint --init-from starts ``role`` from: the file it names, or the role's in the team directory it
    names."""
    source = Path(cfg.init_from)
    return source / f"{role.value}.pt" if source.is_dir() else source


def check_init_from(cfg: TrainConfig, scenario: Scenario) -> None:
    """--init-from: for every trained role a role checkpoint with the learner state and networks of this run's sizes
    (CheckpointError, one line, before any work otherwise)."""
    hidden = sac_config(cfg, scenario).hidden_sizes
    with torch.random.fork_rng():  # a throwaway actor, only for its shapes: the run's random streams stay untouched
        wanted = SquashedGaussianActor(ObservationMode(cfg.observation).size, 2, hidden).state_dict()
    for source in sorted({init_checkpoint(cfg, Role(role)) for role in cfg.roles}):
        have = learner_state(source).get("actor", {})
        shapes = {k: tuple(v.shape) for k, v in have.items()} if isinstance(have, dict) else {}
        if shapes != {k: tuple(v.shape) for k, v in wanted.items()}:
            raise CheckpointError(
                f"--init-from {source}: its actor's layers {sorted(set(shapes.values()))} do not fit this "
                f"run's (hidden_sizes {list(hidden)}, observation {cfg.observation})"
            )
