"""The off-policy training loop of one role (SAC, SAC with a penalty, SAC-Lagrangian, TSSAC; Algorithm 1).

The curriculum trains decoy, then detect (with the trained decoy flying), then strike (with both
flying). TSSAC initialises each role from the previous role's networks (transfer N1 -> N2 -> N3);
every other algorithm trains each role from scratch with the same kind of teammates (its own earlier
roles).
"""

from __future__ import annotations

import collections
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch
from tqdm import tqdm

from tssac_core.algos.replay import ReplayBuffer, ReplaySamples
from tssac_core.algos.sac_lagrangian import SacConfig, SacLagrangian, transfer
from tssac_core.deploy.policy import learner_state
from tssac_core.sim.env import RoleTask
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.scenario import ROLES, Role, Scenario
from tssac_core.train.config import TrainConfig, sac_config, selects_within_limit
from tssac_core.train.epoch import EpochLog, log_stop, make_task, reached_stop, ship_role, teammates_for
from tssac_core.train.rundir import (append_metrics, read_resume_state, role_checkpoint, role_position, save_resume_state,
                                     save_trained_role)
from tssac_core.train.validation import EpochSelector

logger = logging.getLogger("tssac_core.train")


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
    selector = EpochSelector(scenario, role, out, cfg.validation_episodes, cfg.seed, teammates, mode, selects_within_limit(cfg),
                             tail=cfg.selection == "tail")
    rng = np.random.default_rng([cfg.seed, role.index])
    return SeedRole(cfg, role, out, task, buffer, selector, rng, task.reset(),
                    recent_costs=collections.deque(maxlen=sac_cfg.cost_window))


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
