"""PPO (Schulman et al. 2017, "Proximal Policy Optimization Algorithms") and PPO-Lagrangian, the
on-policy baselines of the paper's comparison (section 5.2), plus what they share with CPO
(`tssac_core.algos.onpolicy.cpo`): the configuration, the rollout batch, log-probabilities of stored actions of
the squashed-Gaussian policy, the value networks and their regression.

The policy is the same `SquashedGaussianActor` as SAC's, so that `tssac_core.deploy.policy.Policy.load` deploys
a PPO or CPO role unchanged. Reward and cost have separate value networks (ReLU MLPs with the actor's
hidden sizes) and one Adam optimiser for both; the actor has its own.

`Ppo.update` reads like the paper: (PPO-Lag: multiplier step) -> minibatch epochs of the clipped
surrogate (eq. 7) with an entropy bonus, stopped early when the approximate KL passes target_kl ->
value regression of V^r and V^c.

PPO-Lagrangian (Ray et al. 2019, "Benchmarking Safe Exploration in Deep RL"; OmniSafe's `PPOLag`):
the advantage of the surrogate is (A^r - lambda A^c) / (1 + lambda) and lambda >= 0 is a
`DampedLagrangeMultiplier` with k_d = 0 (plain gradient ascent on the constraint violation), fed once
per update with the *measured* mean cost per episode, compared with the per-episode limit C
directly: no conversion to the discounted scale is needed, since an on-policy rollout measures
episode costs. lambda is reported as beta in the metrics.
"""

from __future__ import annotations

import copy
import logging
import math
from dataclasses import dataclass
from typing import NamedTuple, TypedDict, final

import numpy as np
import torch
from torch import nn
from torch.optim.optimizer import StateDict

from tssac_core.algos.lagrange import DampedLagrangeMultiplier, MultiplierState, SignalRule, choose_signal
from tssac_core.algos.networks import SquashedGaussianActor, mlp, tanh_log_abs_det_jacobian
from tssac_core.algos.onpolicy.config import OnPolicyAlgo, OnPolicyConfig
from tssac_core.algos.sac_config import MultiplierSignal

logger = logging.getLogger(__name__)

_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)
_ATANH_CLAMP = 1e-6
"""Stored actions are clamped to +-(1 - 1e-6) before atanh (float32 resolves this next to 1)."""


class OnPolicyBatch(NamedTuple):
    """One rollout, flattened over time and worlds; every tensor has leading size B."""

    observations: torch.Tensor
    actions: torch.Tensor
    """Squashed actions in [-1, 1], as sent to the environment."""
    log_pi_old: torch.Tensor
    """log pi_old(a|s) of the rollout's policy, recomputed from the stored action (`log_prob_of_actions`)."""
    adv_r: torch.Tensor
    adv_c: torch.Tensor
    ret_r: torch.Tensor
    """Regression targets of V^r (GAE advantage + V^r)."""
    ret_c: torch.Tensor
    """Regression targets of V^c."""


@dataclass(frozen=True)
class OnPolicyStats:
    """Scalars of one update (NaN where a figure does not apply to the algorithm)."""

    policy_loss: float
    """PPO: clipped-surrogate loss (minus the entropy bonus), mean over minibatch steps; CPO: minus the
    surrogate E[ratio A^r] after the step."""
    v_r_loss: float
    """1/2 E[(V^r - R^r)^2], mean over minibatch steps."""
    v_c_loss: float
    """1/2 E[(V^c - R^c)^2], mean over minibatch steps."""
    multiplier_loss: float
    """PPO-Lag: J(lambda) = lambda (C - J_c) before lambda's step (eq. 15's form); NaN otherwise."""
    multiplier: float
    """PPO-Lag: lambda used in this update's surrogate; NaN otherwise."""
    v_r_mean: float
    """Mean V^r over the rollout's states."""
    v_c_mean: float
    """Mean V^c over the rollout's states."""
    entropy: float
    """-E[log pi_old(a|s)] over the rollout: a sample estimate of the squashed policy's entropy."""
    approx_kl: float
    """PPO: the last approximate KL measured; CPO: the exact KL of the accepted step."""
    policy_steps: int
    """Optimiser steps of the actor (PPO: minibatch steps; CPO: 1 if a step was accepted, else 0)."""
    value_steps: int
    """Optimiser steps of the value networks."""
    cpo_case: int = -1
    """CPO: the case of its step (`cpo.INFEASIBLE` ... `cpo.NO_COST_GRADIENT`, 0-4); -1 otherwise."""
    step_fraction: float = math.nan
    """CPO: the accepted line-search fraction (0: the step was rejected)."""


# --- pure functions -----------------------------------------------------------------------------


def squashed_gaussian_log_prob(mean: torch.Tensor, log_std: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """log pi(a|s) of a tanh-squashed Gaussian at stored actions a (Haarnoja et al. 2018, appendix C).

    u = atanh(clamp(a, -1 + 1e-6, 1 - 1e-6)), then
    log pi(a|s) = sum_i [log N(u_i; mean_i, std_i) - log(1 - tanh(u_i)^2)];  shapes (B, d) -> (B,).
    The clamp bounds u near +-7.25: an action that rounded to +-1 gets a finite, consistent log-prob.
    """
    u = torch.atanh(actions.clamp(-1.0 + _ATANH_CLAMP, 1.0 - _ATANH_CLAMP))
    z = (u - mean) * torch.exp(-log_std)
    gaussian = -0.5 * z.square() - log_std - _HALF_LOG_2PI
    return (gaussian - tanh_log_abs_det_jacobian(u)).sum(dim=-1)


def gaussian_entropy(log_std: torch.Tensor) -> torch.Tensor:
    """Entropy of the pre-tanh diagonal Gaussian, sum_i (log std_i + 1/2 log(2 pi e)); (B, d) -> (B,)."""
    return (log_std + _HALF_LOG_2PI + 0.5).sum(dim=-1)


def gaussian_kl(
    mean_old: torch.Tensor, log_std_old: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor
) -> torch.Tensor:
    """KL(N_old || N) of diagonal Gaussians, (B, d) -> (B,). tanh is a bijection, so this is also the
    KL of the squashed policies (the measure of CPO's trust region, Achiam et al. 2017 eq. 10)."""
    var_ratio = torch.exp(2.0 * (log_std_old - log_std))
    mean_term = (mean_old - mean).square() * torch.exp(-2.0 * log_std)
    return (log_std - log_std_old + 0.5 * (var_ratio + mean_term) - 0.5).sum(dim=-1)


def clipped_surrogate_loss(
    log_pi_new: torch.Tensor, log_pi_old: torch.Tensor, adv: torch.Tensor, clip: float
) -> torch.Tensor:
    """PPO's clipped surrogate, Schulman et al. 2017 eq. 7, as a loss to minimise:

    ratio = exp(log_pi_new - log_pi_old)
    loss  = -E[min(ratio * adv, clamp(ratio, 1 - clip, 1 + clip) * adv)]
    """
    ratio = torch.exp(log_pi_new - log_pi_old)
    return -torch.min(ratio * adv, ratio.clamp(1.0 - clip, 1.0 + clip) * adv).mean()


def approx_kl(log_pi_new: torch.Tensor, log_pi_old: torch.Tensor) -> torch.Tensor:
    """KL(pi_old || pi_new) estimated on samples of pi_old: E[(ratio - 1) - log ratio] (Schulman's k3,
    as CleanRL's PPO); >= 0 for every sample."""
    log_ratio = log_pi_new - log_pi_old
    return (torch.expm1(log_ratio) - log_ratio).mean()


def lagrangian_advantage(adv_r: torch.Tensor, adv_c: torch.Tensor, multiplier: torch.Tensor | float) -> torch.Tensor:
    """PPO-Lagrangian's advantage (A^r - lambda A^c) / (1 + lambda) (Ray et al. 2019; OmniSafe PPOLag)."""
    return (adv_r - multiplier * adv_c) / (1.0 + multiplier)


def value_loss(value: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Value regression 1/2 E[(V(s) - R)^2] (Schulman et al. 2017, the L^VF term of eq. 9)."""
    return 0.5 * (value - target).square().mean()


def standardise(x: torch.Tensor) -> torch.Tensor:
    """(x - mean) / (std + 1e-8), population std (a single sample becomes 0)."""
    return (x - x.mean()) / (x.std(unbiased=False) + 1e-8)


def normalised_advantages(adv_r: torch.Tensor, adv_c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """A^r standardised, A^c only centred, over the whole rollout (OmniSafe's on-policy buffer).

    Not scaling A^c keeps it in cost units, which CPO's linearised constraint needs (its constraint
    value c is in those units), and does not blow up the noise of V^c into a unit-variance signal
    when a rollout holds few hazard steps. Centring changes no expected gradient (a baseline).
    """
    return standardise(adv_r), adv_c - adv_c.mean()


# --- shared by PPO and CPO ----------------------------------------------------------------------


def log_prob_of_actions(actor: SquashedGaussianActor, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """log pi(a|s) of stored squashed actions under ``actor`` (`squashed_gaussian_log_prob`)."""
    mean, log_std = actor.mean_log_std(obs)
    return squashed_gaussian_log_prob(mean, log_std, actions)


@torch.no_grad()
def sample_actions(actor: SquashedGaussianActor, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Rollout actions a ~ pi(.|s) and their log pi(a|s), recomputed from a as the update will.

    Recomputing (rather than taking the actor's log_pi at the pre-tanh sample) makes the probability
    ratio exactly 1 at the first update step, even for actions that saturate to +-1 in float32.
    """
    actions, _ = actor(obs)
    return actions, log_prob_of_actions(actor, obs, actions)


def value_networks(obs_dim: int, hidden_sizes: tuple[int, ...]) -> tuple[nn.Sequential, nn.Sequential]:
    """V^r and V^c: separate ReLU MLPs obs_dim -> hidden_sizes -> 1."""
    return mlp(obs_dim, hidden_sizes, 1), mlp(obs_dim, hidden_sizes, 1)


def fit_values(
    v_r: nn.Module, v_c: nn.Module, optim: torch.optim.Optimizer, batch: OnPolicyBatch, config: OnPolicyConfig
) -> tuple[float, float, int]:
    """config.epochs passes of minibatch regression of V^r and V^c on the GAE returns; returns the mean
    losses and the number of steps."""
    n = batch.observations.shape[0]
    params = [*v_r.parameters(), *v_c.parameters()]
    r_losses: list[torch.Tensor] = []
    c_losses: list[torch.Tensor] = []
    for _ in range(config.epochs):
        for idx in torch.randperm(n).split(config.minibatch):
            obs = batch.observations[idx]
            loss_r = value_loss(v_r(obs).squeeze(-1), batch.ret_r[idx])
            loss_c = value_loss(v_c(obs).squeeze(-1), batch.ret_c[idx])
            optim.zero_grad()
            (loss_r + loss_c).backward()
            nn.utils.clip_grad_norm_(params, config.max_grad_norm)
            optim.step()
            r_losses.append(loss_r.detach())
            c_losses.append(loss_c.detach())
    return torch.stack(r_losses).mean().item(), torch.stack(c_losses).mean().item(), len(r_losses)


@torch.no_grad()
def evaluate_values(v_r: nn.Module, v_c: nn.Module, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """V^r(s) and V^c(s) for observations (..., obs_dim) -> (...)."""
    return v_r(obs).squeeze(-1), v_c(obs).squeeze(-1)


class NetworksState(TypedDict):
    """The policy and value networks of an on-policy learner, tagged with its algorithm (:func:`networks_state`)."""

    algo: str
    actor: dict[str, torch.Tensor]
    v_r: dict[str, torch.Tensor]
    v_c: dict[str, torch.Tensor]


@final
class PpoState(NetworksState):
    """What :meth:`Ppo.state_dict` returns: the networks, then the optimisers (torch's own state) and the
    multiplier."""

    actor_optim: StateDict
    value_optim: StateDict
    multiplier: MultiplierState


@final
class CpoState(NetworksState):
    """What :meth:`Cpo.state_dict` returns: the networks and the value optimiser (torch's own state)."""

    value_optim: StateDict


def networks_state(algo: OnPolicyAlgo, actor: nn.Module, v_r: nn.Module, v_c: nn.Module) -> NetworksState:
    """The policy and value networks of an on-policy learner, tagged with its algorithm."""
    return {"algo": algo.value, "actor": actor.state_dict(), "v_r": v_r.state_dict(), "v_c": v_c.state_dict()}


def load_networks(state: NetworksState, algo: OnPolicyAlgo, actor: nn.Module, v_r: nn.Module, v_c: nn.Module) -> None:
    """Restore what `networks_state` returned, refusing another algorithm's state."""
    if state.get("algo") != algo.value:
        raise ValueError(f"cannot load a {state.get('algo')} state into a {algo.value} learner")
    actor.load_state_dict(state["actor"])
    v_r.load_state_dict(state["v_r"])
    v_c.load_state_dict(state["v_c"])


def as_batch_tensor(x: np.ndarray | torch.Tensor) -> torch.Tensor:
    """float32 tensor of an observation batch (n, d) or a single observation (d,) as (1, d)."""
    t = torch.as_tensor(x, dtype=torch.float32)
    return t.unsqueeze(0) if t.ndim == 1 else t


# --- the learner ----------------------------------------------------------------------------------


class Ppo:
    """PPO or PPO-Lagrangian: actor, V^r, V^c, their optimisers and (PPO-Lag) the multiplier.
    Deterministic given `torch.manual_seed` (construction, sampling and minibatch order draw from
    torch's global generator)."""

    def __init__(self, obs_dim: int, act_dim: int, config: OnPolicyConfig) -> None:
        if config.algo not in (OnPolicyAlgo.PPO, OnPolicyAlgo.PPO_LAG):
            raise ValueError(f"Ppo runs ppo or ppo_lag, got {config.algo.value}")
        self.obs_dim = obs_dim
        self.act_dim = act_dim
        self.config = config
        self.actor = SquashedGaussianActor(obs_dim, act_dim, config.hidden_sizes)
        self.v_r, self.v_c = value_networks(obs_dim, config.hidden_sizes)
        # eps 1e-5: CleanRL's PPO (the "implementation details" of Huang et al. 2022).
        self.actor_optim = torch.optim.Adam(self.actor.parameters(), lr=config.lr, eps=1e-5)
        self.value_optim = torch.optim.Adam([*self.v_r.parameters(), *self.v_c.parameters()], lr=config.lr, eps=1e-5)
        self.uses_multiplier = config.algo is OnPolicyAlgo.PPO_LAG
        # k_d = 0: the plain Lagrange multiplier, projected onto [0, multiplier_max] after each step.
        self.multiplier = DampedLagrangeMultiplier(
            cost_limit=config.cost_limit,
            k_d=0.0,
            beta_init=config.beta_init,
            lr=config.beta_lr,
            upper=config.multiplier_max,
        )
        # The on-policy rollout measures episode costs: lambda compares their mean with C itself (scale 1).
        self.signal: SignalRule = choose_signal(MultiplierSignal.EPISODE_COST, self.uses_multiplier)

    @torch.no_grad()
    def act(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        """Actions in [-1, 1]: obs (n, obs_dim) -> (n, act_dim)."""
        action, _ = self.actor(as_batch_tensor(obs), deterministic)
        return action.numpy()

    def update(self, batch: OnPolicyBatch, episode_cost: float) -> OnPolicyStats:
        """Multiplier step (PPO-Lag) -> clipped-surrogate epochs -> value regression.

        ``episode_cost``: the measured cost per episode J_c (undiscounted, the scale of C), the
        multiplier's input: lambda <- Adam step on lambda (C - J_c), projected onto >= 0, *before* the
        policy epochs, which then use the new lambda (as OmniSafe's PPOLag).
        """
        cfg = self.config
        if self.uses_multiplier:
            multiplier_loss = self.multiplier.update(self.signal.measured(float(episode_cost))).item()
            multiplier = self.multiplier.beta.item()
        else:
            multiplier_loss = multiplier = math.nan
        with torch.no_grad():
            v_r_mean, v_c_mean = (v.mean().item() for v in evaluate_values(self.v_r, self.v_c, batch.observations))

        n = batch.observations.shape[0]
        adv_r_all, adv_c_all = (
            normalised_advantages(batch.adv_r, batch.adv_c) if cfg.normalize_advantages else (batch.adv_r, batch.adv_c)
        )
        policy_losses: list[torch.Tensor] = []
        kl = 0.0
        stop = False
        for _ in range(cfg.epochs):
            for idx in torch.randperm(n).split(cfg.minibatch):
                obs, log_pi_old = batch.observations[idx], batch.log_pi_old[idx]
                mean, log_std = self.actor.mean_log_std(obs)
                log_pi = squashed_gaussian_log_prob(mean, log_std, batch.actions[idx])
                kl = approx_kl(log_pi.detach(), log_pi_old).item()
                # Checked before the step (as Stable-Baselines3's PPO): no step beyond the target.
                if cfg.target_kl is not None and kl > cfg.target_kl:
                    stop = True
                    break
                adv_r = adv_r_all[idx]
                adv = lagrangian_advantage(adv_r, adv_c_all[idx], multiplier) if self.uses_multiplier else adv_r
                loss = clipped_surrogate_loss(log_pi, log_pi_old, adv, cfg.clip)
                if cfg.ent_coef > 0.0:
                    loss = loss - cfg.ent_coef * gaussian_entropy(log_std).mean()
                self.actor_optim.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(self.actor.parameters(), cfg.max_grad_norm)
                self.actor_optim.step()
                policy_losses.append(loss.detach())
            if stop:
                logger.debug("ppo: approximate KL %.4f > target %.4f, policy epochs stopped", kl, cfg.target_kl)
                break

        # The value networks get all their epochs: the KL stop concerns the policy only (Spinning Up).
        v_r_loss, v_c_loss, value_steps = fit_values(self.v_r, self.v_c, self.value_optim, batch, cfg)
        return OnPolicyStats(
            policy_loss=torch.stack(policy_losses).mean().item() if policy_losses else math.nan,
            v_r_loss=v_r_loss,
            v_c_loss=v_c_loss,
            multiplier_loss=multiplier_loss,
            multiplier=multiplier,
            v_r_mean=v_r_mean,
            v_c_mean=v_c_mean,
            entropy=-batch.log_pi_old.mean().item(),
            approx_kl=kl,
            policy_steps=len(policy_losses),
            value_steps=value_steps,
        )

    def state_dict(self) -> PpoState:
        """Networks, optimisers and the multiplier (share storage with the learner, like torch's)."""
        return {
            **networks_state(self.config.algo, self.actor, self.v_r, self.v_c),
            "actor_optim": self.actor_optim.state_dict(),
            "value_optim": self.value_optim.state_dict(),
            "multiplier": self.multiplier.state_dict(),
        }

    def load_state_dict(self, state: PpoState | CpoState) -> None:
        """Restore what `state_dict` returned (another algorithm's state is refused, by `load_networks`)."""
        load_networks(state, self.config.algo, self.actor, self.v_r, self.v_c)
        if "actor_optim" not in state:
            raise ValueError(f"cannot load a {state['algo']} state into a {self.config.algo.value} learner")
        # Copies: never share Adam moments with another learner loaded from the same dict.
        self.actor_optim.load_state_dict(copy.deepcopy(state["actor_optim"]))
        self.value_optim.load_state_dict(copy.deepcopy(state["value_optim"]))
        self.multiplier.load_state_dict(state["multiplier"])
