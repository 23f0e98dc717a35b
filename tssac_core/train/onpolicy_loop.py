"""On-policy training of one role with PPO, PPO-Lagrangian or CPO: the paper's on-policy baselines.

`train_role_onpolicy` has the contract of `tssac_core.train.loop.train_role`: the role's earlier teammates fly
their trained policies (`teammates_for`), one epoch collects ``cfg.steps_per_epoch`` decisions from
``cfg.envs`` worlds with the current policy and then runs the algorithm's update, every epoch appends a
row to ``metrics.csv`` (the columns of `tssac_core.train.rundir.METRIC_FIELDS`) and writes ``resume/<role>.pt``, and the
end writes ``<role>.pt``. Every role starts from scratch (no transfer).

Metrics columns of the SAC family, filled by the closest on-policy figure (NaN where none applies):

| column                   | PPO / PPO-Lag / CPO                                                    |
| ------------------------ | ---------------------------------------------------------------------- |
| q_r_loss, q_c_loss       | value regression losses of V^r and V^c                                  |
| actor_loss               | PPO: clipped-surrogate loss; CPO: -E[ratio A^r] after the step          |
| beta_loss, beta          | PPO-Lag: the multiplier's loss and lambda; NaN otherwise                |
| beta_minus_xi            | PPO-Lag: lambda (the effective multiplier, k_d = 0); NaN otherwise      |
| alpha_loss, alpha, xi    | NaN                                                                     |
| q_r_mean, qc_mean        | mean V^r and V^c over the rollout's states                              |
| entropy                  | -E[log pi(a|s)] over the rollout's actions                              |
| updates, updates_per_s   | actor optimiser steps (PPO: minibatch steps; CPO: accepted steps)       |

The measured cost per episode J_C (PPO-Lag's multiplier input, CPO's constraint value) is the mean
cost of the last ``cost_window`` finished episodes, with the mean length L of the same episodes; until
an episode has finished it is estimated as (cost per decision in the rollout) x (episode cap in
decisions), with L = that cap: a pessimistic guess, since episodes that end early cost less.
"""

from __future__ import annotations

import io
import logging
import math
import time
from collections import deque
from collections.abc import Iterable
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch
from tqdm import tqdm

from tssac_core.algos.onpolicy.cpo import Cpo
from tssac_core.algos.onpolicy.gae import gae
from tssac_core.algos.onpolicy.ppo import (
    OnPolicyAlgo,
    OnPolicyBatch,
    OnPolicyConfig,
    OnPolicyStats,
    Ppo,
    evaluate_values,
    sample_actions,
)
from tssac_core.deploy.policy import torch_save_atomic
from tssac_core.sim.env import RoleTask
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.scenario import Role, Scenario
from tssac_core.train.config import TrainConfig, onpolicy_config, selects_within_limit
from tssac_core.train.epoch import EpochLog, log_stop, make_task, reached_stop, ship_role, teammates_for
from tssac_core.train.rundir import append_metrics, role_position, save_trained_role
from tssac_core.train.validation import EpochSelector

logger = logging.getLogger(__name__)

Learner = Ppo | Cpo


def make_learner(obs_dim: int, act_dim: int, config: OnPolicyConfig) -> Learner:
    """Ppo for ppo and ppo_lag, Cpo for cpo."""
    return Cpo(obs_dim, act_dim, config) if config.algo is OnPolicyAlgo.CPO else Ppo(obs_dim, act_dim, config)


class Rollout(NamedTuple):
    """One epoch's on-policy data, every array (T, N, ...): T decisions of N worlds."""

    obs: np.ndarray
    actions: np.ndarray
    log_pi: np.ndarray
    """log pi(a|s) of the rollout's policy, recomputed from the stored action (`ppo.sample_actions`)."""
    rewards: np.ndarray
    costs: np.ndarray
    final_obs: np.ndarray
    """Observation after the step, before any reset (s'_t)."""
    terminal: np.ndarray
    """No bootstrap from s'_t: the target was hit (leaving the area bootstraps, like train.py)."""
    ended: np.ndarray
    """The episode ended at this step (terminated or truncated)."""


def make_batch(learner: Learner, rollout: Rollout) -> OnPolicyBatch:
    """GAE of rewards and costs with the learner's value networks, flattened to (T * N, ...)."""
    cfg = learner.config
    obs = torch.as_tensor(rollout.obs, dtype=torch.float32)
    actions = torch.as_tensor(rollout.actions, dtype=torch.float32)
    v_r, v_c = evaluate_values(learner.v_r, learner.v_c, obs)
    next_v_r, next_v_c = evaluate_values(learner.v_r, learner.v_c, torch.as_tensor(rollout.final_obs, dtype=torch.float32))
    terminal = torch.as_tensor(rollout.terminal)
    ended = torch.as_tensor(rollout.ended)
    rewards = torch.as_tensor(rollout.rewards, dtype=torch.float32)
    costs = torch.as_tensor(rollout.costs, dtype=torch.float32)
    adv_r, ret_r = gae(rewards, v_r, next_v_r, terminal, ended, cfg.gamma, cfg.lam)
    adv_c, ret_c = gae(costs, v_c, next_v_c, terminal, ended, cfg.gamma, cfg.lam)
    log_pi_old = torch.as_tensor(rollout.log_pi).flatten()
    return OnPolicyBatch(obs.flatten(0, 1), actions.flatten(0, 1), log_pi_old, adv_r.flatten(), adv_c.flatten(), ret_r.flatten(), ret_c.flatten())


def measured_episode_cost(finished: Iterable[tuple[float, int]], rollout_costs: np.ndarray, episode_decisions: int) -> tuple[float, float]:
    """(J_C, L): mean cost and mean length (decisions) of the given finished episodes; with none, the
    rollout's mean cost per decision times the episode cap, and L = the cap (module docstring)."""
    episodes = list(finished)
    if episodes:
        costs, lengths = zip(*episodes)
        return float(np.mean(costs)), float(np.mean(lengths))
    return float(np.mean(rollout_costs)) * episode_decisions, float(episode_decisions)


def update(learner: Learner, batch: OnPolicyBatch, episode_cost: float, episode_length: float) -> OnPolicyStats:
    """The algorithm's update with the inputs it takes."""
    if isinstance(learner, Cpo):
        return learner.update(batch, episode_cost, episode_length)
    return learner.update(batch, episode_cost)


def stats_columns(stats: OnPolicyStats, update_time_s: float) -> dict[str, float]:
    """The metrics columns of the SAC family filled from an on-policy update (module docstring)."""
    nan = math.nan
    return {
        "q_r_loss": stats.v_r_loss,
        "q_c_loss": stats.v_c_loss,
        "actor_loss": stats.policy_loss,
        "alpha_loss": nan,
        "beta_loss": stats.multiplier_loss,
        "alpha": nan,
        "beta": stats.multiplier,
        "xi": nan,
        "beta_minus_xi": stats.multiplier,
        "q_r_mean": stats.v_r_mean,
        "qc_mean": stats.v_c_mean,
        "entropy": stats.entropy,
        "updates_per_s": stats.policy_steps / update_time_s if update_time_s > 0 else nan,
    }


def train_role_onpolicy(cfg: TrainConfig, scenario: Scenario, role: Role, out: Path, resume: bool, bar: tqdm) -> None:
    """Train one role with cfg.algo in {ppo, ppo_lag, cpo} for cfg.epochs epochs, checkpointing every
    epoch; writes ``<role>.pt``."""
    mode = ObservationMode(cfg.observation)
    state_path = out / "resume" / f"{role.value}.pt"
    config = onpolicy_config(cfg, scenario)
    torch.manual_seed(cfg.seed * 1000 + role.index)
    learner = make_learner(mode.size, 2, config)
    teammates = teammates_for(role, cfg, out)
    task = make_task(cfg, scenario, role, mode, teammates)
    selector = EpochSelector(scenario, role, out, cfg.validation_episodes, cfg.seed, teammates, mode, selects_within_limit(cfg),
                             tail=cfg.selection == "tail")
    finished: deque[tuple[float, int]] = deque(maxlen=config.cost_window)
    ep_len = np.zeros(cfg.envs, dtype=np.int64)
    start_epoch, env_steps, updates = 0, 0, 0
    obs = task.reset()
    if resume and state_path.is_file():
        saved = torch.load(io.BytesIO(state_path.read_bytes()), map_location="cpu", weights_only=False)
        learner.load_state_dict(saved["learner"])
        task.restore(saved["task"])
        obs, ep_len = saved["obs"], saved["ep_len"]
        finished.extend(saved["finished"])
        torch.set_rng_state(saved["torch_rng"])
        start_epoch, env_steps, updates = saved["epoch"], saved["env_steps"], saved["updates"]
        selector.load_state_dict(saved["selector"])
        logger.info("%s: resuming %s after epoch %d (%d env steps)", role.value, cfg.algo, start_epoch, env_steps)
    bar.n = (role_position(cfg, role) * cfg.epochs + start_epoch) * cfg.steps_per_epoch
    bar.refresh()

    epoch = start_epoch

    def write_checkpoint(path: Path) -> None:
        save_trained_role(path, cfg, scenario, role, config.hidden_sizes, learner.actor.state_dict(), learner.state_dict(), env_steps, updates, epoch)

    iters = max(1, cfg.steps_per_epoch // cfg.envs)
    n, obs_dim = cfg.envs, mode.size
    for epoch in range(start_epoch + 1, cfg.epochs + 1):
        log = EpochLog()
        rollout = Rollout(
            obs=np.zeros((iters, n, obs_dim), np.float32),
            actions=np.zeros((iters, n, 2), np.float32),
            log_pi=np.zeros((iters, n), np.float32),
            rewards=np.zeros((iters, n), np.float32),
            costs=np.zeros((iters, n), np.float32),
            final_obs=np.zeros((iters, n, obs_dim), np.float32),
            terminal=np.zeros((iters, n), bool),
            ended=np.zeros((iters, n), bool),
        )
        for t in range(iters):
            t0 = time.perf_counter()
            actions, log_pi = sample_actions(learner.actor, torch.as_tensor(obs, dtype=torch.float32))
            step = task.step(actions.numpy().astype(np.float64), repeat=cfg.action_repeat)
            ended = step.terminated | step.truncated
            rollout.obs[t], rollout.actions[t], rollout.log_pi[t] = obs, actions.numpy(), log_pi.numpy()
            rollout.rewards[t], rollout.costs[t], rollout.final_obs[t] = step.reward, step.cost, step.final_obs
            # Only a hit ends the learner's future; leaving the area bootstraps (train.py, docs/decisions.md).
            rollout.terminal[t], rollout.ended[t] = step.terminated & step.episode_success, ended
            ep_len += 1
            if ended.any():
                log.record_episodes(step, ended)
                finished.extend(zip(step.episode_cost[ended].tolist(), ep_len[ended].tolist()))
                ep_len[ended] = 0
            obs = step.obs
            env_steps += n
            log.env_time += time.perf_counter() - t0
            bar.update(n)

        t1 = time.perf_counter()
        episode_cost, episode_length = measured_episode_cost(finished, rollout.costs, config.episode_steps)
        stats = update(learner, make_batch(learner, rollout), episode_cost, episode_length)
        update_time = time.perf_counter() - t1
        updates += stats.policy_steps
        row = log.row(role, epoch, env_steps, updates, iters * n)
        row.update(stats_columns(stats, update_time))
        row.update(selector.after_epoch(epoch, write_checkpoint))
        append_metrics(out / "metrics.csv", row)
        logger.info(
            "%s %s epoch %d: return %.2f, cost %.2f, measured J_C %.2f over L %.0f, kl %.4f%s",
            role.value, cfg.algo, epoch, row["return"], row["cost"], episode_cost, episode_length, stats.approx_kl,
            f", cpo case {stats.cpo_case}, step fraction {stats.step_fraction:.3g}" if isinstance(learner, Cpo) else "",
        )
        bar.set_postfix(role=role.value, ep=epoch, ret=f"{row['return']:.1f}", cost=f"{row['cost']:.1f}", task=f"{row['task_success']:.2f}")
        if reached_stop(cfg, row):
            log_stop(role, epoch, row)  # no resume state: a kill before the role ships repeats this epoch
            break
        save_onpolicy_resume_state(state_path, learner, task, obs, ep_len, finished, epoch, env_steps, updates, selector)

    ship_role(out, role, selector, write_checkpoint)


def save_onpolicy_resume_state(path: Path, learner: Learner, task: RoleTask, obs: np.ndarray, ep_len: np.ndarray,
                               finished: Iterable[tuple[float, int]], epoch: int, env_steps: int, updates: int,
                               selector: EpochSelector) -> None:
    """Everything needed to continue after this epoch, written atomically (the key "epoch" is what
    train.completed_epochs reads)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    state = {
        "algo": learner.config.algo.value,
        "learner": learner.state_dict(),
        "task": task.snapshot(),
        "obs": obs,
        "ep_len": ep_len.copy(),
        "finished": list(finished),
        "torch_rng": torch.get_rng_state(),
        "epoch": epoch,
        "env_steps": env_steps,
        "updates": updates,
        "selector": selector.state_dict(),
    }
    torch_save_atomic(state, path)
