"""The settings of the on-policy learners (PPO, PPO-Lagrangian, CPO): which algorithm, and its hyperparameters.
Free of torch, so that a command reads its configuration (and answers ``--help``) without it."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass


class OnPolicyAlgo(enum.Enum):
    """The on-policy baselines of the paper's comparison."""

    PPO = "ppo"
    PPO_LAG = "ppo_lag"
    CPO = "cpo"


@dataclass(frozen=True)
class OnPolicyConfig:
    """Hyperparameters of PPO, PPO-Lagrangian and CPO. The paper gives none for its baselines: the
    networks follow Table 3, the rest the algorithms' usual defaults (CleanRL's `ppo_continuous_action`,
    OmniSafe's PPOLag and CPO)."""

    algo: OnPolicyAlgo = OnPolicyAlgo.PPO
    """Which algorithm."""

    hidden_sizes: tuple[int, ...] = (256, 256)
    """Hidden layers of the actor and of both value networks (Table 3: 256, 256, ReLU)."""

    lr: float = 3e-4
    """Adam learning rate of the PPO actor and of the value networks (CPO's actor takes natural
    gradient steps instead)."""

    gamma: float = 0.99
    """Discount per decision of rewards and costs (Table 3)."""

    lam: float = 0.95
    """GAE lambda (Schulman et al. 2016)."""

    clip: float = 0.2
    """PPO's clip range epsilon of the probability ratio (Schulman et al. 2017)."""

    epochs: int = 10
    """Passes over the rollout per update: PPO's policy epochs, and the value regression's (all algorithms)."""

    minibatch: int = 256
    """Minibatch size of those passes."""

    target_kl: float | None = 0.02
    """PPO: stop the policy epochs before a minibatch step once the approximate KL between the
    rollout's policy and the current one exceeds this (None: never)."""

    ent_coef: float = 0.0
    """PPO: weight of the entropy bonus (CleanRL's default for continuous actions, 0). The bonus is the
    pre-tanh Gaussian's entropy: the squashed distribution's has no closed form."""

    max_grad_norm: float = 0.5
    """Gradient-norm clipping of the PPO actor and of the value networks (CleanRL: 0.5)."""

    normalize_advantages: bool = True
    """Standardise A^r and centre A^c over the rollout (`normalised_advantages`)."""

    cost_limit: float = 3.0
    """Cost threshold C per episode, an undiscounted sum of eq. 11's costs (Table 3)."""

    episode_steps: int = 4000
    """Episode cap in decisions (the scenario's cap / action repeat): the episode length assumed when
    the cost per episode has to be estimated from a rollout in which no episode ended."""

    cost_window: int = 20
    """The measured cost per episode (PPO-Lag's multiplier input, CPO's constraint value) is the mean
    over the last this many finished episodes (OmniSafe keeps a window of its EpCost the same way)."""

    beta_init: float = 0.0
    """PPO-Lag: initial multiplier lambda (reported as beta)."""

    beta_lr: float = 0.05
    """PPO-Lag: Adam learning rate of lambda, one step per update. Adam moves lambda by about this
    much per epoch, so lambda can reach ~2.5 within the paper's 50 epochs (OmniSafe: 0.035 over far
    more epochs)."""

    multiplier_max: float = math.inf
    """PPO-Lag: upper bound of lambda. Unbounded by default: the (1 + lambda) normalisation keeps the
    surrogate's scale whatever lambda is."""

    max_kl: float = 0.01
    """CPO: trust region delta, KL(pi_old || pi_new) <= delta (Achiam et al. 2017)."""

    damping: float = 0.1
    """CPO: Fisher-vector products use F + damping * I."""

    cg_iters: int = 10
    """CPO: conjugate gradient iterations per solve."""

    cg_tol: float = 1e-10
    """CPO: conjugate gradient stops once the residual norm is below this."""

    backtrack_iters: int = 10
    """CPO: line search tries step fractions backtrack_coef^k for k < backtrack_iters."""

    backtrack_coef: float = 0.8
    """CPO: line search shrink factor."""

    def __post_init__(self) -> None:
        checks = [
            (0.0 <= self.gamma < 1.0, f"gamma must be in [0, 1), got {self.gamma}"),
            (0.0 <= self.lam <= 1.0, f"lam must be in [0, 1], got {self.lam}"),
            (self.lr > 0.0, f"lr must be > 0, got {self.lr}"),
            (0.0 < self.clip < 1.0, f"clip must be in (0, 1), got {self.clip}"),
            (self.epochs >= 1, f"epochs must be >= 1, got {self.epochs}"),
            (self.minibatch >= 1, f"minibatch must be >= 1, got {self.minibatch}"),
            (self.target_kl is None or self.target_kl > 0.0, f"target_kl must be > 0 or None, got {self.target_kl}"),
            (self.ent_coef >= 0.0, f"ent_coef must be >= 0, got {self.ent_coef}"),
            (self.max_grad_norm > 0.0, f"max_grad_norm must be > 0, got {self.max_grad_norm}"),
            (self.cost_limit >= 0.0, f"cost_limit must be >= 0, got {self.cost_limit}"),
            (self.episode_steps >= 1, f"episode_steps must be >= 1, got {self.episode_steps}"),
            (self.cost_window >= 1, f"cost_window must be >= 1, got {self.cost_window}"),
            (self.beta_init >= 0.0, f"beta_init must be >= 0, got {self.beta_init}"),
            (self.beta_lr > 0.0, f"beta_lr must be > 0, got {self.beta_lr}"),
            (self.multiplier_max > 0.0, f"multiplier_max must be > 0, got {self.multiplier_max}"),
            (self.max_kl > 0.0, f"max_kl must be > 0, got {self.max_kl}"),
            (self.damping >= 0.0, f"damping must be >= 0, got {self.damping}"),
            (self.cg_iters >= 1, f"cg_iters must be >= 1, got {self.cg_iters}"),
            (self.backtrack_iters >= 1, f"backtrack_iters must be >= 1, got {self.backtrack_iters}"),
            (0.0 < self.backtrack_coef < 1.0, f"backtrack_coef must be in (0, 1), got {self.backtrack_coef}"),
            (len(self.hidden_sizes) >= 1, "hidden_sizes must not be empty"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)
