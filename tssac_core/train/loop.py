"""The training loop of one role, for every learner (Algorithm 1's inner loop).

Each epoch collects ``cfg.steps_per_epoch`` decisions from ``cfg.envs`` worlds, with the learner's hooks
around every step and at the epoch's end (`RoleLearner`): the off-policy learners (the SAC family,
:class:`tssac_core.train.learners.OffPolicyLearner`) store each transition and take their gradient steps as they
go, the on-policy ones (:class:`tssac_core.train.learners.OnPolicyLearner`) store the rollout and update after it.
Then the epoch's checkpoint is validated (:mod:`tssac_core.train.validation`), its row appended to ``metrics.csv``,
and the resume state written (:mod:`tssac_core.train.resume`); at the end the best epoch ships as ``<role>.pt``.

The curriculum trains decoy, then detect (with the trained decoy flying), then strike (with both
flying). TSSAC initialises each role from the previous role's networks (transfer N1 -> N2 -> N3);
every other algorithm trains each role from scratch with the same kind of teammates (its own earlier
roles).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from tssac_core.sim.env import RoleTask
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.scenario import Role, Scenario
from tssac_core.train.algorithms import Selection
from tssac_core.train.config import TrainConfig, selection_of, selects_within_limit
from tssac_core.train.epoch import EpochLog, log_stop, make_task, reached_stop, ship_role, teammates_for
from tssac_core.train.learners import RoleLearner, make_role_learner, transfer_source
from tssac_core.train.resume import ResumeState, read_resume_state, write_resume_state
from tssac_core.train.rundir import MetricsRow, append_metrics, role_position, save_trained_role
from tssac_core.train.validation import EpochSelector

logger = logging.getLogger("tssac_core.train")


def collect_epoch(
    cfg: TrainConfig,
    learner: RoleLearner,
    task: RoleTask,
    obs: np.ndarray,
    env_steps: int,
    updates: int,
    iters: int,
    log: EpochLog,
    bar: tqdm,
) -> tuple[np.ndarray, int, int]:
    """One epoch's ``iters`` decisions in the parallel worlds (Algorithm 1, lines 4-13), the learner storing each and
    updating as it is due; returns the last observations and the decision and update counts after it."""
    learner.begin_epoch(iters)
    for _ in range(iters):
        t0 = time.perf_counter()
        action = learner.act(obs, env_steps)
        step = task.step(action, repeat=cfg.action_repeat)
        ended = step.terminated | step.truncated
        learner.store(obs, action, step, ended)
        obs = step.obs
        env_steps += cfg.envs
        if ended.any():
            log.record_episodes(step, ended)
        t1 = time.perf_counter()
        log.env_time += t1 - t0
        updates += learner.after_step(env_steps, updates, log, t1)
        bar.update(cfg.envs)
    return obs, env_steps, updates


def start_or_resume(
    cfg: TrainConfig, role: Role, out: Path, resume: bool, learner: RoleLearner, task: RoleTask, selector: EpochSelector
) -> tuple[np.ndarray, int, int, int]:
    """The role's start: its resume state restored into the learner, the worlds, torch's generator and the epoch
    selector (``resume`` and one is there), or the learner started (from the previous role, for the algorithms that
    transfer). Returns the observations, the last finished epoch, and the decision and update counts."""
    obs = task.reset()
    saved = read_resume_state(out, role) if resume else None
    if saved is None:
        learner.start(transfer_source(cfg, role, out))
        return obs, 0, 0, 0
    learner.restore(saved.learner)
    task.restore(saved.task)
    torch.set_rng_state(saved.torch_rng)
    selector.load_state_dict(saved.selector)
    logger.info("%s: resuming %s after epoch %d (%d env steps)", role.value, cfg.algo, saved.epoch, saved.env_steps)
    return saved.obs, saved.epoch, saved.env_steps, saved.updates


def train_role(
    cfg: TrainConfig,
    scenario: Scenario,
    role: Role,
    out: Path,
    resume: bool,
    bar: tqdm,
    on_epoch: Callable[[MetricsRow], None] | None = None,
) -> None:
    """Train one role for cfg.epochs epochs, checkpointing every epoch; writes ``<role>.pt``. ``on_epoch`` is
    given every epoch's metrics row (what ``metrics.csv`` gets) once it is written."""
    mode = ObservationMode(cfg.observation)
    torch.manual_seed(cfg.seed * 1000 + role.index)
    learner = make_role_learner(cfg, scenario, role, mode)  # its initial weights are the generator's first draws
    teammates = teammates_for(role, cfg, out)
    task = make_task(cfg, scenario, role, mode, teammates)
    selector = EpochSelector(
        scenario,
        role,
        out,
        cfg.validation_episodes,
        cfg.seed,
        teammates,
        mode,
        selects_within_limit(cfg),
        tail=selection_of(cfg) is Selection.TAIL,
    )
    obs, epoch, env_steps, updates = start_or_resume(cfg, role, out, resume, learner, task, selector)
    bar.n = (role_position(cfg, role) * cfg.epochs + epoch) * cfg.steps_per_epoch
    bar.refresh()

    def write_checkpoint(path: Path) -> None:
        actor_state, learner_state = learner.checkpoint_states()
        save_trained_role(
            path, cfg, scenario, role, learner.hidden_sizes, actor_state, learner_state, env_steps, updates, epoch
        )

    iters = max(1, cfg.steps_per_epoch // cfg.envs)
    done = epoch
    for epoch in range(done + 1, cfg.epochs + 1):
        log = EpochLog()
        obs, env_steps, updates = collect_epoch(cfg, learner, task, obs, env_steps, updates, iters, log, bar)
        made, columns = learner.end_epoch(log)
        updates += made
        row = log.row(role, epoch, env_steps, updates, iters * cfg.envs)
        row.figures.update(columns)
        row.figures.update(selector.after_epoch(epoch, write_checkpoint))
        append_metrics(out / "metrics.csv", row)
        if on_epoch is not None:
            on_epoch(row)
        learner.log_epoch(epoch, row)
        bar.set_postfix(
            role=role.value,
            ep=epoch,
            ret=f"{row.figures['return']:.1f}",
            cost=f"{row.figures['cost']:.1f}",
            task=f"{row.figures['task_success']:.2f}",
        )
        if reached_stop(cfg, row):
            # No resume state for this epoch: a kill before the role ships repeats it (from the same state).
            log_stop(role, epoch, row)
            break
        write_resume_state(
            out,
            role,
            ResumeState(
                cfg.algo,
                epoch,
                env_steps,
                updates,
                task.state(),
                obs,
                torch.get_rng_state(),
                selector.state_dict(),
                learner.state(),
            ),
        )

    ship_role(out, role, selector, write_checkpoint)
