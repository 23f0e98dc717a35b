"""The loop's hooks for each learner family (`tssac_core.train.loop.RoleLearner`).

`OffPolicyLearner` (tssac, sac_lag, sac, sac_penalty): a replay buffer, uniform random actions for the
first ``start_steps`` decisions of a role trained from scratch, one gradient update per ``update_every``
decisions once the buffer holds ``update_after`` transitions (Algorithm 1), TSSAC's transfer at the start.

`OnPolicyLearner` (ppo, ppo_lag, cpo): one rollout of the epoch's decisions with the current policy,
then GAE and the algorithm's update. Metrics columns of the SAC family, filled by the closest on-policy
figure (NaN where none applies):

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

import collections
import logging
import math
import time
from collections import deque
from collections.abc import Iterable
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from tssac_core.algos.onpolicy.cpo import Cpo
from tssac_core.algos.onpolicy.gae import gae
from tssac_core.algos.onpolicy.ppo import (
    CpoState,
    OnPolicyAlgo,
    OnPolicyBatch,
    OnPolicyConfig,
    OnPolicyStats,
    Ppo,
    PpoState,
    evaluate_values,
    sample_actions,
)
from tssac_core.algos.replay import ReplayBuffer
from tssac_core.algos.sac_lagrangian import SacLagrangian, SacState, transfer
from tssac_core.common.errors import CheckpointError
from tssac_core.deploy.policy import learner_state
from tssac_core.sim.env import TaskStep
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.scenario import ROLES, Role, Scenario
from tssac_core.train.algorithms import algorithm
from tssac_core.train.config import TrainConfig, onpolicy_config, sac_config
from tssac_core.train.epoch import EpochLog
from tssac_core.train.resume import LearnerResume, OffPolicyResume, OnPolicyResume, pcg64_state
from tssac_core.train.rundir import MetricsRow, init_checkpoint, role_checkpoint

logger = logging.getLogger("tssac_core.train")


def transfer_source(cfg: TrainConfig, role: Role, out: Path) -> Path | None:
    """The checkpoint a fresh role starts from: --init-from (a checkpoint, or a team's directory: its checkpoint of the
    role), TSSAC's previous role (N_k -> N_k+1), or none."""
    if cfg.init_from:
        return init_checkpoint(cfg, role)
    if algorithm(cfg.algo).transfers and role.index > 0:
        return role_checkpoint(cfg, out, ROLES[role.index - 1])
    return None


class OffPolicyLearner:
    """SacLagrangian with its replay buffer and exploration (module docstring)."""

    def __init__(self, cfg: TrainConfig, scenario: Scenario, role: Role, mode: ObservationMode) -> None:
        self.cfg, self.role = cfg, role
        self.sac_cfg = sac_config(cfg, scenario)
        self.learner = SacLagrangian(mode.size, 2, self.sac_cfg)
        self.hidden_sizes = self.sac_cfg.hidden_sizes
        self.buffer = ReplayBuffer(mode.size, 2, min(self.sac_cfg.replay_size, cfg.epochs * cfg.steps_per_epoch))
        self.rng = np.random.default_rng([cfg.seed, role.index])
        self.transferred = False
        self.recent_costs: deque[float] = collections.deque(maxlen=self.sac_cfg.cost_window)
        """The learner's costs of the last finished episodes (a measurement the multiplier's signal may be)."""

    def start(self, source: Path | None) -> None:
        """A fresh role: TSSAC's transfer, or --init-from (fine-tuning)."""
        if source is None:
            return
        try:
            copied = transfer(self.learner, learner_state(source))
        except (RuntimeError, KeyError) as exc:  # load_state_dict: size mismatch, missing or unexpected tensors
            first = str(exc).strip().splitlines()[-1].strip() if str(exc).strip() else type(exc).__name__
            raise CheckpointError(
                f"{source}: its networks do not fit this run's (hidden_sizes {list(self.hidden_sizes)}, "
                f"observation {self.cfg.observation}): {first}"
            ) from None
        self.transferred = True
        verb = "initialised" if self.cfg.init_from else "transferred"
        logger.info("%s: %s %d tensors from %s", self.role.value, verb, len(copied), source)

    def begin_epoch(self, iters: int) -> None:
        pass

    def act(self, obs: np.ndarray, env_steps: int) -> np.ndarray:
        # From-scratch roles act uniformly at random for cfg.start_steps decisions first.
        if env_steps < self.cfg.start_steps and not self.transferred:
            return self.rng.uniform(-1.0, 1.0, (self.cfg.envs, 2))
        return self.learner.act(obs, deterministic=False)

    def store(self, obs: np.ndarray, action: np.ndarray, step: TaskStep, ended: np.ndarray) -> None:
        # Only a hit ends the learner's future: leaving the area ends the episode too, but the
        # critics bootstrap through it (like the cap), so that ending an episode early is never
        # a way out of the step penalty or of the hazard cost (docs/decisions.md).
        self.buffer.add_batch(
            obs, action, step.reward, step.cost, step.final_obs, step.terminated & step.episode_success
        )
        if ended.any():
            self.recent_costs.extend(step.episode_cost[ended].tolist())

    def after_step(self, env_steps: int, updates: int, log: EpochLog, t1: float) -> int:
        """The gradient updates owed after this step (Algorithm 1: one per update_every decisions), none while
        the buffer holds fewer than update_after transitions; returns how many it made."""
        if len(self.buffer) < self.cfg.update_after:
            return 0
        due = env_steps // self.cfg.update_every - updates
        sac_cfg, learner = self.sac_cfg, self.learner
        window = learner.signal.recent_window  # transitions drawn for the signal only when it is Q^c on them
        for _ in range(due):
            batch = self.buffer.sample(sac_cfg.batch_size, self.rng)
            recent = self.buffer.sample_recent(sac_cfg.batch_size, window, self.rng) if window is not None else None
            log.stats.append(learner.update(batch, recent, self.episode_cost()))
        log.update_time += time.perf_counter() - t1
        return max(due, 0)

    def episode_cost(self) -> float:
        """The mean learner cost of the recent finished episodes (0 before the first ends)."""
        return float(np.mean(self.recent_costs)) if self.recent_costs else 0.0

    def end_epoch(self, log: EpochLog) -> tuple[int, dict[str, float]]:
        return 0, {}

    def log_epoch(self, epoch: int, row: MetricsRow) -> None:
        pass

    def checkpoint_states(self) -> tuple[dict[str, torch.Tensor], SacState]:
        state = self.learner.state_dict()
        return state["actor"], state

    def state(self) -> OffPolicyResume:
        return {
            "learner": self.learner.state_dict(),
            "buffer": self.buffer.state_dict(),
            "rng": pcg64_state(self.rng),
            "transferred": self.transferred,
            "recent_costs": list(self.recent_costs),
        }

    def restore(self, state: LearnerResume) -> None:
        if "buffer" not in state:
            raise CheckpointError("an on-policy learner's resume state cannot resume an off-policy learner")
        self.learner.load_state_dict(state["learner"])
        self.buffer.load_state_dict(state["buffer"])
        self.rng.bit_generator.state = state["rng"]
        self.transferred = state["transferred"]
        self.recent_costs = collections.deque(state.get("recent_costs", []), maxlen=self.recent_costs.maxlen)


Learner = Ppo | Cpo


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
    """No bootstrap from s'_t: the target was hit (leaving the area bootstraps, as off-policy)."""
    ended: np.ndarray
    """The episode ended at this step (terminated or truncated)."""


def make_batch(learner: Learner, rollout: Rollout) -> OnPolicyBatch:
    """GAE of rewards and costs with the learner's value networks, flattened to (T * N, ...)."""
    cfg = learner.config
    obs = torch.as_tensor(rollout.obs, dtype=torch.float32)
    actions = torch.as_tensor(rollout.actions, dtype=torch.float32)
    v_r, v_c = evaluate_values(learner.v_r, learner.v_c, obs)
    next_v_r, next_v_c = evaluate_values(
        learner.v_r, learner.v_c, torch.as_tensor(rollout.final_obs, dtype=torch.float32)
    )
    terminal = torch.as_tensor(rollout.terminal)
    ended = torch.as_tensor(rollout.ended)
    rewards = torch.as_tensor(rollout.rewards, dtype=torch.float32)
    costs = torch.as_tensor(rollout.costs, dtype=torch.float32)
    adv_r, ret_r = gae(rewards, v_r, next_v_r, terminal, ended, cfg.gamma, cfg.lam)
    adv_c, ret_c = gae(costs, v_c, next_v_c, terminal, ended, cfg.gamma, cfg.lam)
    log_pi_old = torch.as_tensor(rollout.log_pi).flatten()
    return OnPolicyBatch(
        obs.flatten(0, 1),
        actions.flatten(0, 1),
        log_pi_old,
        adv_r.flatten(),
        adv_c.flatten(),
        ret_r.flatten(),
        ret_c.flatten(),
    )


def measured_episode_cost(
    finished: Iterable[tuple[float, int]], rollout_costs: np.ndarray, episode_decisions: int
) -> tuple[float, float]:
    """(J_C, L): mean cost and mean length (decisions) of the given finished episodes; with none, the
    rollout's mean cost per decision times the episode cap, and L = the cap (module docstring)."""
    episodes = list(finished)
    if episodes:
        costs, lengths = zip(*episodes)
        return float(np.mean(costs)), float(np.mean(lengths))
    return float(np.mean(rollout_costs)) * episode_decisions, float(episode_decisions)


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


class OnPolicyLearner:
    """Ppo (ppo, ppo_lag) or Cpo (cpo) with its rollout (module docstring). Every role starts from scratch."""

    def __init__(self, cfg: TrainConfig, scenario: Scenario, role: Role, mode: ObservationMode) -> None:
        self.cfg, self.role, self.mode = cfg, role, mode
        self.config: OnPolicyConfig = onpolicy_config(cfg, scenario)
        self.learner: Learner = (Cpo if self.config.algo is OnPolicyAlgo.CPO else Ppo)(mode.size, 2, self.config)
        self.hidden_sizes = self.config.hidden_sizes
        self.finished: deque[tuple[float, int]] = deque(maxlen=self.config.cost_window)
        self.ep_len = np.zeros(cfg.envs, dtype=np.int64)
        self._t = 0
        self._last: tuple[np.ndarray, np.ndarray] | None = None
        self._summary = ""

    def start(self, source: Path | None) -> None:
        pass  # no transfer; --init-from is refused for the on-policy learners (train.config.check_learner_settings)

    def begin_epoch(self, iters: int) -> None:
        n, obs_dim = self.cfg.envs, self.mode.size
        self.rollout = Rollout(
            obs=np.zeros((iters, n, obs_dim), np.float32),
            actions=np.zeros((iters, n, 2), np.float32),
            log_pi=np.zeros((iters, n), np.float32),
            rewards=np.zeros((iters, n), np.float32),
            costs=np.zeros((iters, n), np.float32),
            final_obs=np.zeros((iters, n, obs_dim), np.float32),
            terminal=np.zeros((iters, n), bool),
            ended=np.zeros((iters, n), bool),
        )
        self._t = 0

    def act(self, obs: np.ndarray, env_steps: int) -> np.ndarray:
        actions, log_pi = sample_actions(self.learner.actor, torch.as_tensor(obs, dtype=torch.float32))
        self._last = (actions.numpy(), log_pi.numpy())
        return actions.numpy().astype(np.float64)

    def store(self, obs: np.ndarray, action: np.ndarray, step: TaskStep, ended: np.ndarray) -> None:
        assert self._last is not None
        t, r = self._t, self.rollout
        r.obs[t], r.actions[t], r.log_pi[t] = obs, self._last[0], self._last[1]
        r.rewards[t], r.costs[t], r.final_obs[t] = step.reward, step.cost, step.final_obs
        # Only a hit ends the learner's future; leaving the area bootstraps (as off-policy, docs/decisions.md).
        r.terminal[t], r.ended[t] = step.terminated & step.episode_success, ended
        self.ep_len += 1
        if ended.any():
            self.finished.extend(zip(step.episode_cost[ended].tolist(), self.ep_len[ended].tolist()))
            self.ep_len[ended] = 0
        self._t += 1

    def after_step(self, env_steps: int, updates: int, log: EpochLog, t1: float) -> int:
        return 0

    def end_epoch(self, log: EpochLog) -> tuple[int, dict[str, float]]:
        """GAE over the rollout, then the algorithm's update with the measured cost (module docstring)."""
        t1 = time.perf_counter()
        episode_cost, episode_length = measured_episode_cost(
            self.finished, self.rollout.costs, self.config.episode_steps
        )
        batch = make_batch(self.learner, self.rollout)
        if isinstance(self.learner, Cpo):
            stats = self.learner.update(batch, episode_cost, episode_length)
        else:
            stats = self.learner.update(batch, episode_cost)
        update_time = time.perf_counter() - t1
        cpo = (
            f", cpo case {stats.cpo_case}, step fraction {stats.step_fraction:.3g}"
            if isinstance(self.learner, Cpo)
            else ""
        )
        self._summary = f"measured J_C {episode_cost:.2f} over L {episode_length:.0f}, kl {stats.approx_kl:.4f}{cpo}"
        return stats.policy_steps, stats_columns(stats, update_time)

    def log_epoch(self, epoch: int, row: MetricsRow) -> None:
        logger.info(
            "%s %s epoch %d: return %.2f, cost %.2f, %s",
            self.role.value,
            self.cfg.algo,
            epoch,
            row.figures["return"],
            row.figures["cost"],
            self._summary,
        )

    def checkpoint_states(self) -> tuple[dict[str, torch.Tensor], PpoState | CpoState]:
        return self.learner.actor.state_dict(), self.learner.state_dict()

    def state(self) -> OnPolicyResume:
        return {
            "algo": self.config.algo.value,
            "learner": self.learner.state_dict(),
            "ep_len": self.ep_len.copy(),
            "finished": list(self.finished),
        }

    def restore(self, state: LearnerResume) -> None:
        if "ep_len" not in state:
            raise CheckpointError("an off-policy learner's resume state cannot resume an on-policy learner")
        self.learner.load_state_dict(state["learner"])
        self.ep_len = state["ep_len"]
        self.finished.extend(state["finished"])


RoleLearner = OffPolicyLearner | OnPolicyLearner


def make_role_learner(cfg: TrainConfig, scenario: Scenario, role: Role, mode: ObservationMode) -> RoleLearner:
    """The hooks of cfg.algo's family, with freshly initialised networks (drawn from torch's global generator)."""
    return (OffPolicyLearner if algorithm(cfg.algo).off_policy else OnPolicyLearner)(cfg, scenario, role, mode)
