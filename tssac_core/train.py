"""``python -m tssac_core.train``: train the team, role by role (Algorithm 1).

Examples::

    python -m tssac_core.train --algo tssac --seed 0 --out runs/tssac-0
    python -m tssac_core.train --algo sac_lag --seed 1 --epochs 20 --out runs/sac_lag-1
    python -m tssac_core.train --out runs/tssac-0 --resume        # after a crash or kill -9

The curriculum trains decoy, then detect (with the trained decoy flying), then strike (with both
flying). TSSAC initialises each role from the previous role's networks (transfer N1 -> N2 -> N3);
every other algorithm trains each role from scratch with the same kind of teammates (its own earlier
roles). Output in ``--out``: ``config.json``, ``metrics.csv`` (one row per role and epoch), one
checkpoint per role (``decoy.pt``, ``detect.pt``, ``strike.pt``), ``fig7_return_cost.png`` and
``fig8_multiplier.png``, and ``resume/`` (the last completed epoch: learner, replay buffer, worlds and
random states), from which ``--resume`` continues, losing at most the epoch that was running.
"""

from __future__ import annotations

import argparse
import collections
import csv
import dataclasses
import io
import json
import logging
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch
from tqdm import tqdm

from tssac_core.algos.replay import ReplayBuffer, ReplaySamples
from tssac_core.algos.sac_lagrangian import MULTIPLIER_VARIANTS, SacConfig, SacLagrangian, UpdateStats, Variant, transfer
from tssac_core.cli import UsageError, run, write_json
from tssac_core.env import RoleTask, TaskStep
from tssac_core.numpy_actor import export_actor
from tssac_core.observation import ObservationMode
from tssac_core.policy import CheckpointInfo, Policy, learner_state, package_versions, save_role_checkpoint, torch_save_atomic
from tssac_core.reward import RewardConfig
from tssac_core.routes import RouteConfig
from tssac_core.scenario import ROLES, Role, Scenario, load
from tssac_core.team import Pilot
from tssac_core.validation import EpochSelector

logger = logging.getLogger(__name__)
DEFAULT_SCENARIO = Path(__file__).resolve().parent.parent / "scenarios" / "random.yaml"
SAC_FAMILY = {v.value: v for v in Variant}
ON_POLICY = ("ppo", "ppo_lag", "cpo")
ALGOS = (*SAC_FAMILY, *ON_POLICY)


@dataclass(frozen=True)
class TrainConfig:
    """One training run: an algorithm, a seed, the role curriculum."""

    algo: str = "tssac"
    """tssac, sac_lag, sac, sac_penalty (off-policy, tssac_core.algos.sac_lagrangian) or ppo, ppo_lag, cpo
    (on-policy, tssac_core.train_onpolicy)."""
    scenario: str = str(DEFAULT_SCENARIO)
    """Scenario file (random layouts: every episode a new one, section 5.2.3)."""
    seed: int = 0
    epochs: int = 50
    """Epochs per role (Table 3: 50)."""
    steps_per_epoch: int = 4000
    """Environment steps per epoch, summed over the parallel worlds (Table 3: 4,000)."""
    roles: tuple[str, ...] = ("decoy", "detect", "strike")
    """Roles to train, in curriculum order; earlier roles must already be in --out (or in ``teammates``)."""
    envs: int = 4
    """Parallel worlds collecting experience (one batched world)."""
    update_every: int = 1
    """Gradient updates happen once per this many environment steps (1: one update per step, as Algorithm 1)."""
    start_steps: int = 4000
    """From-scratch roles act uniformly at random for this many steps first (not after transfer)."""
    update_after: int = 1000
    """No updates before the buffer holds this many transitions."""
    observation: str = "route"
    """paper (eq. 7), extended, or route (extended + the way around the radars; tssac_core.observation)."""
    action_repeat: int = 1
    """Decision interval: the learner's action is held for this many 0.1 s world steps (1: the paper)."""
    penalty: float = 0.0
    """sac_penalty: reward r + penalty * c."""
    threads: int = 2
    """torch threads (this machine has 2 cores)."""
    route_margin_km: float = 3.0
    """Reward: the way around the radars keeps this far from them (tssac_core.routes.RouteConfig)."""
    cost_margin_km: float = 1.0
    """The learner's cost counts steps within this distance of a radar, not only inside it: a tightened
    constraint, so that the policy keeps clear of the radars' edges (docs/decisions.md). Evaluation,
    validation and the hazard_cost column count eq. 11 exactly."""
    validation_episodes: int = 30
    """After every epoch, fly this many held-out missions with the greedy policy; the best epoch is shipped
    (tssac_core.validation). 0: ship the last epoch."""
    init_from: str = ""
    """A role checkpoint whose networks initialise every trained role (fine-tuning; transfer() resets the rest)."""
    teammates: str = ""
    """A directory of trained role checkpoints (a run, or ``models/tssac``) for the earlier roles this run does
    not train: they fly beside the trained roles and, for TSSAC, are transferred from. "" (default): this
    run's own --out (the curriculum)."""
    stop_at_task_success: float = 0.0
    """End a role after the first epoch whose task success in training reaches this fraction (0: train every
    epoch). For measuring how many decisions a role needs to reach a level, as the transfer experiment does."""
    selection: str = ""
    """Which validated epoch a role ships (tssac_core.validation): "within_limit", the best mission success
    among the epochs within the cost limit; "success", the best mission success whatever the cost. "" (the
    default): the algorithm's own, "within_limit" for the learners that are given the limit
    (CONSTRAINED_ALGOS), "success" for those that are not (sac, sac_penalty, ppo)."""
    sac: dict[str, Any] = field(default_factory=dict)
    """Overrides of SacConfig fields (Table 3 defaults)."""


def role_checkpoint(cfg: TrainConfig, out: Path, role: Role) -> Path:
    """Where a trained earlier role is: in this run if it trains that role (or has no ``teammates``), else in ``teammates``."""
    if cfg.teammates and role.value not in cfg.roles:
        return Path(cfg.teammates) / f"{role.value}.pt"
    return out / f"{role.value}.pt"


def teammates_for(role: Role, cfg: TrainConfig, out: Path) -> dict[str, Pilot]:
    """Earlier roles fly their trained policies (the judgement condition); later ones are parked."""
    pilots: dict[str, Pilot] = {}
    for earlier in ROLES[: role.index]:
        pilots[earlier.value] = Policy.load(role_checkpoint(cfg, out, earlier), earlier)
    return pilots


def reached_stop(cfg: TrainConfig, row: dict[str, Any]) -> bool:
    """The epoch's training task success reached ``cfg.stop_at_task_success`` (never when that is 0)."""
    return cfg.stop_at_task_success > 0 and row["task_success"] >= cfg.stop_at_task_success


SAC_MULTIPLIER_ALGOS = tuple(algo for algo, variant in SAC_FAMILY.items() if variant in MULTIPLIER_VARIANTS)
"""The SAC family's algorithms with a learned multiplier (SacConfig.multiplier_signal matters)."""

CONSTRAINED_ALGOS = (*SAC_MULTIPLIER_ALGOS, "ppo_lag", "cpo")
"""The learners that are given the cost limit C: they ship the best epoch within it (TrainConfig.selection)."""
SELECTIONS = ("within_limit", "success")

OLDER_RUN_SETTINGS = {"cost_margin_km": 0.0, "selection": "within_limit"}
"""Settings that a config.json written before they existed means (those runs trained on eq. 11 exactly, and
every algorithm shipped the best epoch within the cost limit)."""


def selects_within_limit(cfg: TrainConfig) -> bool:
    """Whether the run ships the best epoch within the cost limit (TrainConfig.selection, resolved)."""
    return (cfg.selection or default_selection(cfg.algo)) == "within_limit"


def default_selection(algo: str) -> str:
    """TrainConfig.selection's default: a learner that is not given the cost limit is not judged by it either."""
    return "within_limit" if algo in CONSTRAINED_ALGOS else "success"


def config_from_saved(saved: Any, source: str | Path = "config.json") -> TrainConfig:
    """The TrainConfig of a run's config.json; keys it lacks take their value from before they existed.

    A file that is not a training configuration of this TSSAC (not a mapping, settings it does not know,
    no roles) raises UsageError naming ``source``.
    """
    if not isinstance(saved, dict):
        raise UsageError(f"{source}: not a training configuration")
    unknown = sorted(set(saved) - {f.name for f in dataclasses.fields(TrainConfig)})
    if unknown:
        raise UsageError(f"{source}: settings this TSSAC does not know: {', '.join(unknown)}")
    full = {**OLDER_RUN_SETTINGS, **saved}
    if not isinstance(full.get("roles"), list):
        raise UsageError(f"{source}: roles: expected a list of role names")
    if full.get("algo") in SAC_MULTIPLIER_ALGOS and isinstance(full.get("sac"), dict) and "multiplier_signal" not in full["sac"]:
        full["sac"] = {**full["sac"], "multiplier_signal": "q_c"}  # what their multiplier measured before the setting
    if full["selection"] not in SELECTIONS:
        raise UsageError(f"{source}: selection: expected one of {', '.join(SELECTIONS)}, got {full['selection']!r}")
    return TrainConfig(**{**full, "roles": tuple(full["roles"])})


def with_recorded_defaults(cfg: TrainConfig) -> TrainConfig:
    """``cfg`` with the settings whose default changed written out, so that a run's config.json records
    which it used: TSSAC's and SAC-Lagrangian's multiplier_signal in ``sac`` ("q_c" before), and the
    epoch selection (every algorithm's was "within_limit" before)."""
    if cfg.algo in SAC_MULTIPLIER_ALGOS and "multiplier_signal" not in cfg.sac:
        cfg = dataclasses.replace(cfg, sac={**cfg.sac, "multiplier_signal": SacConfig.multiplier_signal})
    if not cfg.selection:
        cfg = dataclasses.replace(cfg, selection=default_selection(cfg.algo))
    return cfg


def reward_config(cfg: TrainConfig) -> RewardConfig:
    return RewardConfig(route=RouteConfig(margin_m=cfg.route_margin_km * 1000.0))


def make_task(cfg: TrainConfig, scenario: Scenario, role: Role, mode: ObservationMode, teammates: dict[str, Pilot]) -> RoleTask:
    """The training worlds of one role: its reward, its (tightened) cost, its teammates, its seed."""
    return RoleTask(scenario, role, cfg.envs, mode, teammates=teammates, seed=cfg.seed * 1000 + role.index,
                    reward_config=reward_config(cfg), cost_margin_m=cfg.cost_margin_km * 1000.0)


def sac_config(cfg: TrainConfig, scenario: Scenario) -> SacConfig:
    # The learner's episode is counted in decisions: the Q^c limit converts C over that many.
    decisions = math.ceil(scenario.episode_steps / cfg.action_repeat)
    fields = {"variant": SAC_FAMILY[cfg.algo], "cost_limit": scenario.cost_limit, "episode_steps": decisions}
    if cfg.algo == "sac_penalty":
        fields["penalty"] = cfg.penalty
    fields.update(cfg.sac)
    if "hidden_sizes" in fields:
        fields["hidden_sizes"] = tuple(fields["hidden_sizes"])
    return SacConfig(**fields)


@dataclass
class EpochLog:
    """Accumulates one epoch's figures."""

    returns: list[float] = field(default_factory=list)
    costs: list[float] = field(default_factory=list)
    hazard_costs: list[float] = field(default_factory=list)
    tasks: list[float] = field(default_factory=list)
    successes: list[float] = field(default_factory=list)
    stats: list[UpdateStats] = field(default_factory=list)
    env_time: float = 0.0
    update_time: float = 0.0

    def record_episodes(self, step: TaskStep, ended: np.ndarray) -> None:
        """Add the figures of the episodes that ended at this step (``ended``, (N,) bool)."""
        self.returns += step.episode_return[ended].tolist()
        self.costs += step.episode_cost[ended].tolist()
        self.hazard_costs += step.episode_hazard_cost[ended].tolist()
        self.tasks += step.episode_task[ended].astype(float).tolist()
        self.successes += step.episode_success[ended].astype(float).tolist()

    def row(self, role: Role, epoch: int, env_steps: int, updates: int, steps: int) -> dict[str, Any]:
        def mean(xs: list[float]) -> float:
            return float(np.mean(xs)) if xs else math.nan

        row: dict[str, Any] = {
            "role": role.value,
            "epoch": epoch,
            "env_steps": env_steps,
            "episodes": len(self.returns),
            "return": mean(self.returns),
            "cost": mean(self.costs),
            "hazard_cost": mean(self.hazard_costs),
            "task_success": mean(self.tasks),
            "mission_success": mean(self.successes),
        }
        for f in dataclasses.fields(UpdateStats):
            row[f.name] = mean([getattr(s, f.name) for s in self.stats])
        row["env_steps_per_s"] = steps / self.env_time if self.env_time > 0 else math.nan
        row["updates_per_s"] = len(self.stats) / self.update_time if self.update_time > 0 else math.nan
        row["updates"] = updates
        return row


@dataclass
class SeedRole:
    """One seed's side of training one role: its worlds, replay buffer, validation, random state and
    counters. The learner is the caller's (one `SacLagrangian`, or one seed of a K-seed learner)."""

    cfg: TrainConfig
    role: Role
    out: Path
    task: RoleTask
    buffer: ReplayBuffer
    selector: EpochSelector
    rng: np.random.Generator
    obs: np.ndarray
    epoch: int = 0
    """The epoch running, or the last one completed between epochs."""
    env_steps: int = 0
    updates: int = 0
    transferred: bool = False
    recent_costs: collections.deque[float] = field(default_factory=collections.deque)
    """The learner's costs of the last finished episodes, SacConfig.cost_window of them (maxlen; the
    multiplier's measurement with multiplier_signal "episode_cost")."""

    @property
    def state_path(self) -> Path:
        return self.out / "resume" / f"{self.role.value}.pt"

    def exploring(self) -> bool:
        """From-scratch roles act uniformly at random for cfg.start_steps decisions first."""
        return self.env_steps < self.cfg.start_steps and not self.transferred

    def random_action(self) -> np.ndarray:
        return self.rng.uniform(-1.0, 1.0, (self.cfg.envs, 2))

    def collect(self, action: np.ndarray, log: EpochLog) -> None:
        """One step of the worlds with ``action``: into the replay buffer, finished episodes into ``log``."""
        cfg = self.cfg
        step = self.task.step(action, repeat=cfg.action_repeat)
        # Only a hit ends the learner's future: leaving the area ends the episode too, but the
        # critics bootstrap through it (like the cap), so that ending an episode early is never
        # a way out of the step penalty or of the hazard cost (docs/decisions.md).
        self.buffer.add_batch(self.obs, action, step.reward, step.cost, step.final_obs, step.terminated & step.episode_success)
        self.obs = step.obs
        self.env_steps += cfg.envs
        ended = step.terminated | step.truncated
        if ended.any():
            log.record_episodes(step, ended)
            self.recent_costs.extend(step.episode_cost[ended].tolist())

    def updates_due(self) -> int | None:
        """Gradient updates owed after the last step (Algorithm 1: one per update_every decisions);
        None while the buffer holds fewer than update_after transitions."""
        if len(self.buffer) < self.cfg.update_after:
            return None
        return self.env_steps // self.cfg.update_every - self.updates

    def sample(self, sac_cfg: SacConfig, uses_multiplier: bool) -> tuple[ReplaySamples, ReplaySamples | None]:
        """One update's minibatch, and (multiplier_signal "q_c") the recent batch on which the
        multiplier measures Q^c."""
        batch = self.buffer.sample(sac_cfg.batch_size, self.rng)
        window = sac_cfg.multiplier_window if sac_cfg.multiplier_signal == "q_c" else None
        recent = self.buffer.sample_recent(sac_cfg.batch_size, window, self.rng) if window and uses_multiplier else None
        return batch, recent

    def episode_cost(self, sac_cfg: SacConfig, uses_multiplier: bool) -> float | None:
        """Multiplier_signal "episode_cost": the mean learner cost of the recent finished episodes (0
        before the first ends); None otherwise (the learner measures Q^c)."""
        if not uses_multiplier or sac_cfg.multiplier_signal != "episode_cost":
            return None
        return float(np.mean(self.recent_costs)) if self.recent_costs else 0.0

    def end_epoch(self, log: EpochLog, iters: int, write_checkpoint: Callable[[Path], None]) -> dict[str, Any]:
        """Validate the epoch's checkpoint and append its metrics row; returns the row."""
        row = log.row(self.role, self.epoch, self.env_steps, self.updates, iters * self.cfg.envs)
        row.update(self.selector.after_epoch(self.epoch, write_checkpoint))
        append_metrics(self.out / "metrics.csv", row)
        return row

    def restore(self, saved: dict[str, Any]) -> None:
        """Continue from a resume state (`resume_state`); the learner's part is the caller's."""
        self.buffer.load_state_dict(saved["buffer"])
        self.task.restore(saved["task"])
        self.obs = saved["obs"]
        self.rng.bit_generator.state = saved["rng"]
        self.epoch, self.env_steps, self.updates, self.transferred = saved["epoch"], saved["env_steps"], saved["updates"], saved["transferred"]
        # Absent from resume states older than SacConfig.multiplier_signal.
        self.recent_costs = collections.deque(saved.get("recent_costs", []), maxlen=self.recent_costs.maxlen)
        self.selector.load_state_dict(saved["selector"])
        logger.info("%s: resuming after epoch %d (%d env steps)", self.role.value, self.epoch, self.env_steps)

    def resume_state(self, learner_state: dict[str, Any], torch_rng: torch.Tensor) -> dict[str, Any]:
        """Everything needed to continue after this epoch."""
        return {
            "learner": learner_state,
            "buffer": self.buffer.state_dict(),
            "task": self.task.snapshot(),
            "obs": self.obs,
            "rng": self.rng.bit_generator.state,
            "torch_rng": torch_rng,
            "epoch": self.epoch,
            "env_steps": self.env_steps,
            "updates": self.updates,
            "transferred": self.transferred,
            "recent_costs": list(self.recent_costs),
            "selector": self.selector.state_dict(),
        }

    def write_checkpoint(self, path: Path, scenario: Scenario, hidden_sizes: tuple[int, ...], learner_state: dict[str, Any]) -> None:
        save_trained_role(path, self.cfg, scenario, self.role, hidden_sizes, learner_state["actor"], learner_state,
                          self.env_steps, self.updates, self.epoch)


def open_seed_role(cfg: TrainConfig, scenario: Scenario, role: Role, out: Path, sac_cfg: SacConfig) -> SeedRole:
    """A seed's worlds (reset), replay buffer, validation selector and exploration generator for ``role``."""
    mode = ObservationMode(cfg.observation)
    buffer = ReplayBuffer(mode.size, 2, min(sac_cfg.replay_size, cfg.epochs * cfg.steps_per_epoch))
    teammates = teammates_for(role, cfg, out)
    task = make_task(cfg, scenario, role, mode, teammates)
    selector = EpochSelector(scenario, role, out, cfg.validation_episodes, cfg.seed, teammates, mode, selects_within_limit(cfg))
    rng = np.random.default_rng([cfg.seed, role.index])
    return SeedRole(cfg, role, out, task, buffer, selector, rng, task.reset(),
                    recent_costs=collections.deque(maxlen=sac_cfg.cost_window))


def read_resume_state(path: Path) -> dict[str, Any] | None:
    if not path.is_file():
        return None
    return torch.load(io.BytesIO(path.read_bytes()), map_location="cpu", weights_only=False)


def transfer_source(cfg: TrainConfig, role: Role, out: Path) -> Path | None:
    """The checkpoint a fresh role starts from: --init-from, TSSAC's previous role (N_k -> N_k+1), or none."""
    if cfg.init_from:
        return Path(cfg.init_from)
    if cfg.algo == "tssac" and role.index > 0:
        return role_checkpoint(cfg, out, ROLES[role.index - 1])
    return None


def log_transfer(role: Role, cfg: TrainConfig, copied: list[str], source: Path) -> None:
    verb = "initialised" if cfg.init_from else "transferred"
    logger.info("%s: %s %d tensors from %s", role.value, verb, len(copied), source)


def train_role(cfg: TrainConfig, scenario: Scenario, role: Role, out: Path, resume: bool, bar: tqdm) -> None:
    """Train one role for cfg.epochs epochs, checkpointing every epoch; writes ``<role>.pt``."""
    mode = ObservationMode(cfg.observation)
    sac_cfg = sac_config(cfg, scenario)
    torch.manual_seed(cfg.seed * 1000 + role.index)
    learner = SacLagrangian(mode.size, 2, sac_cfg)
    run = open_seed_role(cfg, scenario, role, out, sac_cfg)
    saved = read_resume_state(run.state_path) if resume else None
    source = transfer_source(cfg, role, out)
    if saved is not None:
        learner.load_state_dict(saved["learner"])
        run.restore(saved)
        torch.set_rng_state(saved["torch_rng"])
    elif source is not None:
        log_transfer(role, cfg, transfer(learner, learner_state(source)), source)
        run.transferred = True
    bar.n = (role_position(cfg, role) * cfg.epochs + run.epoch) * cfg.steps_per_epoch
    bar.refresh()

    def write_checkpoint(path: Path) -> None:
        run.write_checkpoint(path, scenario, sac_cfg.hidden_sizes, learner.state_dict())

    iters = max(1, cfg.steps_per_epoch // cfg.envs)
    for epoch in range(run.epoch + 1, cfg.epochs + 1):
        run.epoch = epoch
        log = EpochLog()
        for _ in range(iters):
            t0 = time.perf_counter()
            run.collect(run.random_action() if run.exploring() else learner.act(run.obs, deterministic=False), log)
            t1 = time.perf_counter()
            log.env_time += t1 - t0
            due = run.updates_due()
            if due is not None:
                for _ in range(due):
                    batch, recent = run.sample(sac_cfg, learner.uses_multiplier)
                    log.stats.append(learner.update(batch, recent, run.episode_cost(sac_cfg, learner.uses_multiplier)))
                run.updates += max(due, 0)
                log.update_time += time.perf_counter() - t1
            bar.update(cfg.envs)
        row = run.end_epoch(log, iters, write_checkpoint)
        bar.set_postfix(role=role.value, ep=epoch, ret=f"{row['return']:.1f}", cost=f"{row['cost']:.1f}", task=f"{row['task_success']:.2f}")
        if reached_stop(cfg, row):
            # No resume state for this epoch: a kill before the role ships repeats it (from the same state).
            log_stop(role, epoch, row)
            break
        save_resume_state(run.state_path, run.resume_state(learner.state_dict(), torch.get_rng_state()))

    ship_role(out, role, run.selector, write_checkpoint)


def log_stop(role: Role, epoch: int, row: dict[str, Any]) -> None:
    logger.info("%s: task success %.2f in epoch %d (%d decisions) reaches --stop-at-task-success: role done", role.value,
                row["task_success"], epoch, row["env_steps"])


def ship_role(out: Path, role: Role, selector: EpochSelector, write_checkpoint: Callable[[Path], None]) -> None:
    """Write ``<role>.pt``: the best validated epoch's checkpoint (without validation, the last epoch's),
    and its actor as ``<role>.npz`` (tssac_core.numpy_actor)."""
    best = selector.finish(out / f"{role.value}.pt", write_checkpoint)
    if (out / f"{role.value}.pt").is_file():
        export_actor(out / f"{role.value}.pt")  # <role>.npz: what the companion flies, without torch
    if best is not None:
        logger.info("%s: shipping epoch %d (validation: mission success %.2f, cost %.2f)", role.value, best.epoch,
                    best.mission_success, best.mean_cost)


def save_trained_role(path: Path, cfg: TrainConfig, scenario: Scenario, role: Role, hidden_sizes: tuple[int, ...],
                      actor_state: dict[str, torch.Tensor], learner_state: dict[str, Any], env_steps: int, updates: int, epoch: int) -> None:
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


def save_resume_state(path: Path, state: dict[str, Any]) -> None:
    """Write a resume state (`SeedRole.resume_state`) atomically."""
    path.parent.mkdir(parents=True, exist_ok=True)
    torch_save_atomic(state, path)


METRIC_FIELDS = ["role", "epoch", "env_steps", "episodes", "return", "cost", "task_success", "mission_success",
                 *[f.name for f in dataclasses.fields(UpdateStats)], "env_steps_per_s", "updates_per_s", "updates",
                 "val_mission_success", "val_task_success", "val_cost", "best_epoch", "hazard_cost"]


def append_metrics(path: Path, row: dict[str, Any]) -> None:
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
        writer.writerow(row)


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


def completed_epochs(out: Path, role: str) -> int:
    """Epochs of ``role`` that a resume can skip: all if its checkpoint exists, else the resume state's."""
    if (out / f"{role}.pt").is_file():
        return -1
    state = out / "resume" / f"{role}.pt"
    if state.is_file():
        return int(torch.load(io.BytesIO(state.read_bytes()), map_location="cpu", weights_only=False)["epoch"])
    return 0


def parse_args(argv: Sequence[str] | None) -> tuple[TrainConfig, Path, bool, bool]:
    """The run's TrainConfig, --out, --resume and --no-progress (see `parse_cli` for --seeds)."""
    cfg, out, resume, quiet, _ = parse_cli(argv)
    return cfg, out, resume, quiet


def parse_seeds(text: str) -> tuple[int, ...]:
    try:
        seeds = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise UsageError(f"--seeds: {text!r} is not a comma-separated list of integers") from None
    if not seeds or len(set(seeds)) != len(seeds):
        raise UsageError(f"--seeds: give one or more distinct seeds, got {text!r}")
    return seeds


def parse_cli(argv: Sequence[str] | None) -> tuple[TrainConfig, Path, bool, bool, tuple[int, ...] | None]:
    p = argparse.ArgumentParser(prog="python -m tssac_core.train", description=__doc__.split("\n")[0])
    p.add_argument("--algo", choices=ALGOS, default="tssac", help="learner (default tssac: SAC-Lagrangian, damped multiplier, transfer)")
    p.add_argument("--scenario", type=Path, default=DEFAULT_SCENARIO, help="scenario file (default scenarios/random.yaml)")
    p.add_argument("--seed", type=int, default=0, help="seed of networks, layouts and exploration")
    p.add_argument("--seeds", help="train these seeds (e.g. 0,1,2) in one process with one batched learner, into --out/seed<N>/ "
                   "(SAC family only; replaces --seed)")
    p.add_argument("--epochs", type=int, default=50, help="epochs per role (Table 3: 50)")
    p.add_argument("--steps-per-epoch", type=int, default=4000, help="learner decisions per epoch (Table 3: 4000)")
    p.add_argument("--roles", default="decoy,detect,strike", help="comma-separated, in curriculum order")
    p.add_argument("--envs", type=int, default=4, help="parallel worlds (default 4)")
    p.add_argument("--update-every", type=int, default=1, help="one gradient update per this many decisions (default 1)")
    p.add_argument("--start-steps", type=int, default=4000, help="uniform random actions for this many decisions first (from-scratch roles)")
    p.add_argument("--update-after", type=int, default=1000, help="no updates before the buffer holds this many transitions")
    p.add_argument("--action-repeat", type=int, default=1, help="hold each action for this many 0.1 s world steps (default 1)")
    p.add_argument("--observation", choices=[m.value for m in ObservationMode], default="route", help="observation (default route = extended + the way around the radars; paper = eq. 7)")
    p.add_argument("--penalty", type=float, default=0.0, help="sac_penalty: reward r + penalty * c (e.g. -10)")
    p.add_argument("--route-margin-km", type=float, default=3.0, help="reward and route observation: the way to the zone keeps this far from the radars (default 3)")
    p.add_argument("--cost-margin-km", type=float, default=1.0, help="the learner's cost counts steps within this distance of a radar (default 1; 0: eq. 11 exactly)")
    p.add_argument("--validation-episodes", type=int, default=30, help="held-out missions flown after every epoch to pick the shipped one (0: ship the last epoch)")
    p.add_argument("--selection", choices=SELECTIONS, help="which validated epoch a role ships: the best mission success among the "
                   "epochs within the cost limit (within_limit: default of tssac, sac_lag, ppo_lag, cpo), or whatever the cost "
                   "(success: default of sac, sac_penalty, ppo)")
    p.add_argument("--init-from", type=Path, help="initialise the learner of every trained role from this role checkpoint (fine-tuning)")
    p.add_argument("--teammates", type=Path, help="directory whose trained earlier roles fly beside (and, for tssac, transfer to) "
                   "the trained roles, e.g. models/tssac with --roles strike (default: --out itself)")
    p.add_argument("--stop-at-task-success", type=float, default=0.0, metavar="FRACTION",
                   help="end a role after the first epoch whose task success in training reaches this (e.g. 0.9; default 0: never)")
    p.add_argument("--threads", type=int, default=2, help="torch threads (default 2: this machine's cores)")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE", help="override a learner setting (SacConfig or OnPolicyConfig field), e.g. --set lr=3e-4 or --set multiplier_signal=q_c")
    p.add_argument("--out", type=Path, required=True, help="run directory (config, metrics, checkpoints, plots, resume state)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out (its config.json wins)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    a = p.parse_args(argv)
    roles = tuple(r.strip() for r in a.roles.split(",") if r.strip())
    for r in roles:
        if r not in [x.value for x in ROLES]:
            raise UsageError(f"--roles: unknown role {r!r}")
    if list(roles) != [x.value for x in ROLES if x.value in roles]:
        raise UsageError("--roles must follow the curriculum order decoy, detect, strike")
    if min(a.epochs, a.steps_per_epoch, a.envs, a.update_every, a.action_repeat) <= 0:
        raise UsageError("--epochs, --steps-per-epoch, --envs, --update-every and --action-repeat must be positive")
    if min(a.validation_episodes, a.route_margin_km, a.cost_margin_km) < 0:
        raise UsageError("--validation-episodes, --route-margin-km and --cost-margin-km must be >= 0")
    if not 0.0 <= a.stop_at_task_success <= 1.0:
        raise UsageError(f"--stop-at-task-success must be a fraction in [0, 1], got {a.stop_at_task_success:g}")
    overrides: dict[str, Any] = {}
    for item in a.set:
        key, _, value = item.partition("=")
        try:
            overrides[key] = json.loads(value)
        except json.JSONDecodeError:
            overrides[key] = value  # a word, e.g. multiplier_signal=q_c; SacConfig checks it
    cfg = TrainConfig(
        algo=a.algo, scenario=str(a.scenario), seed=a.seed, epochs=a.epochs, steps_per_epoch=a.steps_per_epoch, roles=roles,
        envs=a.envs, update_every=a.update_every, start_steps=a.start_steps, update_after=a.update_after,
        observation=a.observation, action_repeat=a.action_repeat, penalty=a.penalty, threads=a.threads, sac=overrides,
        validation_episodes=a.validation_episodes, route_margin_km=a.route_margin_km, cost_margin_km=a.cost_margin_km,
        init_from=str(a.init_from) if a.init_from else "", teammates=str(a.teammates) if a.teammates else "",
        stop_at_task_success=a.stop_at_task_success, selection=a.selection or "",
    )
    return cfg, a.out, a.resume, a.no_progress, parse_seeds(a.seeds) if a.seeds is not None else None


def main(argv: Sequence[str] | None = None) -> int:
    cfg, out, resume, quiet, seeds = parse_cli(argv)
    from tssac_core.train_kseed import is_kseed_run, train_seeds

    if seeds is not None or (resume and is_kseed_run(out)):
        return train_seeds(cfg, seeds, out, resume, quiet)
    cfg, scenario = prepare_run(cfg, out, resume)
    torch.set_num_threads(cfg.threads)
    total = len(cfg.roles) * cfg.epochs * cfg.steps_per_epoch
    start = time.perf_counter()
    with tqdm(total=total, desc=f"{cfg.algo} seed {cfg.seed}", unit="step", disable=quiet, file=sys.stderr, smoothing=0.05) as bar:
        for role_name in cfg.roles:
            role = Role(role_name)
            if (out / f"{role_name}.pt").is_file():
                logger.info("%s: already trained (%s)", role_name, out / f"{role_name}.pt")
                continue
            if cfg.algo in ON_POLICY:
                from tssac_core.train_onpolicy import train_role_onpolicy

                train_role_onpolicy(cfg, scenario, role, out, resume, bar)
            else:
                train_role(cfg, scenario, role, out, resume, bar)
            write_plots(out, scenario.cost_limit)
    write_plots(out, scenario.cost_limit)
    print(f"trained {', '.join(cfg.roles)} with {cfg.algo} (seed {cfg.seed}) in {time.perf_counter() - start:.0f} s; results in {out}")
    return 0


def prepare_run(cfg: TrainConfig, out: Path, resume: bool) -> tuple[TrainConfig, Scenario]:
    """Check the run and set up ``out``: config.json written (or, on --resume, read: it wins), earlier roles
    present, metrics of epochs that were not checkpointed dropped. Returns the run's config and scenario."""
    config_path = out / "config.json"
    if resume:
        if not config_path.is_file():
            raise UsageError(f"--resume: {config_path} not found (nothing to resume)")
        try:
            saved = json.loads(config_path.read_text())
        except (OSError, ValueError) as exc:
            raise UsageError(f"--resume: {config_path} is not readable ({exc})") from None
        cfg = config_from_saved(saved, config_path)
    elif config_path.is_file():
        raise UsageError(f"{out} already holds a run; use --resume to continue it or choose another --out")
    else:
        cfg = with_recorded_defaults(cfg)
    scenario = load(cfg.scenario)
    check_learner_settings(cfg, scenario)
    for role_name in cfg.roles:
        role = Role(role_name)
        for earlier in ROLES[: role.index]:
            path = role_checkpoint(cfg, out, earlier)
            if earlier.value not in cfg.roles and not path.is_file():
                raise UsageError(f"training {role.value} needs {path} (train {earlier.value} first)")
    out.mkdir(parents=True, exist_ok=True)
    if not resume:
        write_json(config_path, {**dataclasses.asdict(cfg), "roles": list(cfg.roles)})
    keep = set()
    for role_name in cfg.roles:
        done = completed_epochs(out, role_name)
        keep |= {(role_name, e) for e in range(1, (cfg.epochs if done < 0 else done) + 1)}
    truncate_metrics(out / "metrics.csv", keep)
    return cfg, scenario


def check_learner_settings(cfg: TrainConfig, scenario: Scenario) -> None:
    """Build the algorithm's config once, so that a bad --set fails before any work, in one line."""
    try:
        if cfg.algo in ON_POLICY:
            from tssac_core.train_onpolicy import OnPolicyConfig, onpolicy_config

            check_override_kinds(cfg.sac, OnPolicyConfig)
            onpolicy_config(cfg, scenario)
        else:
            check_override_kinds(cfg.sac, SacConfig)
            for key in cfg.sac:
                if key not in {f.name for f in dataclasses.fields(SacConfig)} or key == "variant":
                    raise ValueError(f"unknown SacConfig field {key!r}")
            sac_config(cfg, scenario)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"invalid learner settings (--set): {exc}") from None


def check_override_kinds(overrides: dict[str, Any], config: type) -> None:
    """A word (``--set key=word``) only for a setting that is a word, such as multiplier_signal, and a
    number, list or boolean for every other: ValueError naming the key."""
    words = {f.name for f in dataclasses.fields(config) if isinstance(f.default, str)}
    for key, value in overrides.items():
        if isinstance(value, str) != (key in words):
            expected = "a word" if key in words else "a number, list or boolean"
            raise ValueError(f"{key}: expected {expected}, got {value!r}")


def write_plots(out: Path, cost_limit: float) -> None:
    from tssac_core.plots import plot_training

    plot_training(out / "metrics.csv", out, cost_limit)


if __name__ == "__main__":
    sys.exit(run(main))
