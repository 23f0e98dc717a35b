"""SAC, SAC with a hazard penalty, SAC-Lagrangian and TSSAC's learner (paper section 4, eq. 12-17).

One flat class, `SacLagrangian`, owns the networks, their targets, the optimisers, alpha and the
multiplier; `update` reads like the paper: targets (eq. 13) -> critic losses (eq. 13) -> actor loss
(eq. 12 / 16) -> alpha (eq. 14) -> multiplier (eq. 15, 17) -> Polyak averaging of the targets.
The four variants differ only in the multiplier of Q^c in the actor loss and in the reward:

| variant     | reward          | multiplier of Q^c in the actor loss             |
| ----------- | --------------- | ----------------------------------------------- |
| SAC         | r               | 0 (cost critic still trained, for logging)      |
| SAC_PENALTY | r + penalty * c | 0 (cost critic still trained, for logging)      |
| SAC_LAG     | r               | beta (eq. 12, 15)                               |
| TSSAC       | r               | beta - xi, xi = k_d (C - Q^c) (eq. 16, 17)      |

TSSAC's transfer (Algorithm 1, N1 -> N2 -> N3) is `transfer`.
"""

from __future__ import annotations

import copy
import enum
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from tssac_core.algos import losses
from tssac_core.algos.lagrange import DampedLagrangeMultiplier, qc_limit
from tssac_core.algos.networks import Critic, SquashedGaussianActor
from tssac_core.algos.replay import ReplaySamples

logger = logging.getLogger(__name__)


class Variant(enum.Enum):
    """Which algorithm of the paper's comparison the learner runs."""

    SAC = "sac"
    SAC_PENALTY = "sac_penalty"
    SAC_LAG = "sac_lag"
    TSSAC = "tssac"


MULTIPLIER_VARIANTS = (Variant.SAC_LAG, Variant.TSSAC)
"""The variants that learn the cost multiplier beta (eq. 15)."""


class MultiplierSignal(enum.StrEnum):
    """SacConfig.multiplier_signal: what eq. 15 and 17 compare with C (a str: it reads as its word)."""

    EPISODE_COST = "episode_cost"
    """The mean measured cost of the last `cost_window` training episodes, on Q^c's scale."""
    Q_C = "q_c"
    """The mean Q^c of the current policy on recent transitions (eq. 15 literally)."""


@dataclass(frozen=True)
class SacConfig:
    """Hyperparameters; defaults are the paper's Table 3 unless a field says otherwise."""

    variant: Variant = Variant.TSSAC
    """The algorithm (see the module docstring's table)."""

    hidden_sizes: tuple[int, ...] = (256, 256)
    """Hidden layer sizes of the actor and of every critic (Table 3: 256, 256, ReLU)."""

    lr: float = 1e-3
    """Adam learning rate eta of the actor, the critics and alpha (Table 3)."""

    gamma: float = 0.99
    """Discount factor gamma of rewards and costs (Table 3)."""

    polyak: float = 0.995
    """Target averaging: target <- polyak * target + (1 - polyak) * online (Table 3)."""

    batch_size: int = 256
    """Minibatch size; read by the training loop when it samples the replay buffer (Table 3)."""

    replay_size: int = 1_000_000
    """Replay capacity M; read by the training loop when it builds the buffer (Table 3)."""

    target_entropy: float = -1.0
    """Entropy target H0 of eq. 14, in nats, for the whole action (not per dimension) (Table 3)."""

    alpha_init: float = 0.0
    """Initial entropy coefficient (Table 3: 0). alpha is learned directly and projected onto
    >= 0 after each Adam step (like beta), so 0 is a valid start: alpha stays 0 until the policy's
    entropy falls below H0, then rises. A log-alpha parametrisation could not start at 0."""

    beta_init: float = 0.0
    """Initial cost multiplier beta (Table 3: 0)."""

    beta_lr: float = 1e-2
    """Adam learning rate of beta (not in the paper; 10 x lr, as DESIGN.md section 2 asks for a
    larger one). Adam moves beta by about beta_lr per update, so from 0 it can reach ~10 within
    ~1,000 updates (a quarter of a 4,000-step epoch) and fall back as fast once the constraint
    holds; at lr = 1e-3 that would take 2.5 of the paper's 50 epochs."""

    k_d: float = 10.0
    """Damping scale factor k_d of eq. 17 (Table 3); used by TSSAC only (SAC_LAG runs with 0)."""

    cost_limit: float = 3.0
    """Cost threshold C per episode, an undiscounted sum of eq. 11's costs (Table 3). Converted to
    the scale of Q^c with `qc_limit(cost_limit, gamma, episode_steps)`."""

    episode_steps: int = 4000
    """Episode length T used to convert cost_limit for Q^c (Table 3: max 4,000 steps)."""

    penalty: float = 0.0
    """SAC_PENALTY only: reward r + penalty * c, penalty <= 0 (paper's experiment: 0, -10, -15,
    -50). Must be 0 for the other variants."""

    multiplier_signal: MultiplierSignal = MultiplierSignal.EPISODE_COST
    """What eq. 15 and 17 compare with C; read by the training loop, which passes the measurement to
    `update`. "episode_cost": the mean measured cost of the last `cost_window` training episodes,
    converted to Q^c's scale (`cost_on_qc_scale`), as PID-Lagrangian (Stooke et al. 2020) and
    OmniSafe's SAC-Lag measure the constraint, and as our PPO-Lag and CPO do. "q_c": the mean Q^c of
    the current policy on recent transitions (`multiplier_window`), eq. 15's E[Q^c] literally.
    Deviation from the paper (docs/decisions.md; the side-by-side run: results/multiplier-signal/): a
    mean cost critic barely registers the rare long stays inside a radar that make up the tail of the
    episode cost (its mean over an epoch stayed under the limit in epochs whose training episodes
    averaged 5-10 x C), so with "q_c" beta sat near 0 while the role's cost was above C."""

    cost_window: int = 10
    """"episode_cost": the number of most recent finished training episodes averaged (about one
    4,000-decision epoch of 400-decision missions); before the first one ends, the measured cost is 0."""

    multiplier_window: int | None = 4000
    """"q_c": Q^c of eq. 15 and 17 is measured on transitions drawn from the last this many added to
    the replay buffer, i.e. on the current policy's state distribution rho_pi, as eq. 15's expectation
    says (None: on the update's own batch from the whole buffer, as WCSAC does). Deviation from
    common practice, not from the paper: the whole buffer keeps early exploration's states inside
    radars, whose cost-to-go no policy can bring under the limit, so beta would rise for ever."""

    multiplier_max: float = 10.0
    """Upper bound of beta and of the effective multiplier (not in the paper; OmniSafe bounds its
    Lagrange multiplier the same way). Q^c counts discounted hazard steps, the reward about 0.1 per
    step, so a multiplier of 10 already makes one hazard step outweigh ten steps of progress; see
    DampedLagrangeMultiplier."""

    clamp_effective: bool = True
    """Clamp the effective multiplier beta - xi of eq. 16 at >= 0 (see DampedLagrangeMultiplier)."""

    cost_cvar_level: float | None = None
    """None: the actor's cost term is the mean cost-to-go Q^c (eq. 12 / 16). A level in (0, 1): a worst-case cost
    critic as WCSAC's (Yang et al. 2021), layered on the same multiplier: a second network learns the variance
    V^c of the cost-to-go (``losses.cost_variance_target``, ``losses.variance_loss``), and the actor's cost term is
    CVaR_level of N(Q^c, V^c), the mean of the worst ``level`` share of outcomes (``losses.cost_cvar``), so a
    state from which the cost is rare but long weighs more than its mean. Not in the paper; the multiplier's
    signal (eq. 15, 17) is unchanged."""

    def __post_init__(self) -> None:
        checks = [
            (0.0 <= self.gamma < 1.0, f"gamma must be in [0, 1), got {self.gamma}"),
            (0.0 <= self.polyak <= 1.0, f"polyak must be in [0, 1], got {self.polyak}"),
            (self.lr > 0.0, f"lr must be > 0, got {self.lr}"),
            (self.beta_lr > 0.0, f"beta_lr must be > 0, got {self.beta_lr}"),
            (self.alpha_init >= 0.0, f"alpha_init must be >= 0, got {self.alpha_init}"),
            (self.beta_init >= 0.0, f"beta_init must be >= 0, got {self.beta_init}"),
            (self.k_d >= 0.0, f"k_d must be >= 0, got {self.k_d}"),
            (self.multiplier_max > 0.0, f"multiplier_max must be > 0, got {self.multiplier_max}"),
            (self.cost_limit >= 0.0, f"cost_limit must be >= 0, got {self.cost_limit}"),
            (self.episode_steps >= 1, f"episode_steps must be >= 1, got {self.episode_steps}"),
            (
                self.multiplier_signal in list(MultiplierSignal),
                f"multiplier_signal must be one of {', '.join(MultiplierSignal)}, got {self.multiplier_signal!r}",
            ),
            (self.cost_window >= 1, f"cost_window must be >= 1, got {self.cost_window}"),
            (
                self.cost_cvar_level is None or 0.0 < self.cost_cvar_level < 1.0,
                f"cost_cvar_level must be in (0, 1) or None, got {self.cost_cvar_level}",
            ),
            (self.batch_size >= 1, f"batch_size must be >= 1, got {self.batch_size}"),
            (self.replay_size >= 1, f"replay_size must be >= 1, got {self.replay_size}"),
            (len(self.hidden_sizes) >= 1, "hidden_sizes must not be empty"),
            (self.penalty <= 0.0, f"penalty must be <= 0 (r + penalty * c), got {self.penalty}"),
            (
                self.penalty == 0.0 or self.variant is Variant.SAC_PENALTY,
                f"penalty is used only by variant sac_penalty, got {self.penalty} with {self.variant.value}",
            ),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)
        object.__setattr__(self, "multiplier_signal", MultiplierSignal(self.multiplier_signal))

    @property
    def qc_limit(self) -> float:
        """The cost limit C on the scale of Q^c (see `lagrange.qc_limit`)."""
        return qc_limit(self.cost_limit, self.gamma, self.episode_steps)

    def cost_on_qc_scale(self, episode_cost: torch.Tensor | float | Sequence[float]) -> torch.Tensor:
        """A measured cost per episode on Q^c's scale, by the conversion that gives `qc_limit` from C
        (linear: comparing the result with qc_limit is comparing episode_cost with C)."""
        return torch.as_tensor(episode_cost, dtype=torch.float32) * qc_limit(1.0, self.gamma, self.episode_steps)


def fast_adam(params: Sequence[torch.Tensor], lr: float) -> torch.optim.Adam:
    """Adam with torch's fused CPU kernel: one pass over each tensor instead of a chain of
    elementwise kernels (the step on Table 3's critics measured 2.4x faster). The same update
    rule; the rounding of the result can differ in the last bit from the default implementation."""
    try:
        return torch.optim.Adam(params, lr=lr, fused=True)
    except RuntimeError:  # a torch without the fused CPU kernel (< 2.4)
        return torch.optim.Adam(params, lr=lr, foreach=True)


def load_optimiser(optim: torch.optim.Optimizer, state: dict[str, Any]) -> None:
    """`optim.load_state_dict`, keeping optim's own implementation choice (fused / foreach):
    a loaded param group brings the flags it was saved with (None in older checkpoints)."""
    flags = {key: optim.param_groups[0].get(key) for key in ("fused", "foreach")}
    optim.load_state_dict(state)
    for group in optim.param_groups:
        group.update(flags)


@dataclass(frozen=True)
class UpdateStats:
    """Scalars of one `update`. alpha, beta, xi and beta_minus_xi are the values *used* in this
    update's losses (before alpha's and beta's own steps)."""

    q_r_loss: float
    """Eq. 13 summed over the two reward critics."""
    q_c_loss: float
    """Eq. 13 of the cost critic (with SacConfig.cost_cvar_level: plus the variance critic's loss)."""
    actor_loss: float
    """Eq. 12 / 16."""
    alpha_loss: float
    """Eq. 14."""
    beta_loss: float
    """Eq. 15 (0 for SAC and SAC_PENALTY, whose beta is not learned)."""
    alpha: float
    """Entropy coefficient of eq. 12-14."""
    beta: float
    """Cost multiplier of eq. 12 / 15 (0 for SAC and SAC_PENALTY)."""
    xi: float
    """Eq. 17 (0 unless TSSAC)."""
    beta_minus_xi: float
    """The effective multiplier of Q^c in the actor loss, after the clamp if clamp_effective."""
    q_r_mean: float
    """Batch mean of min_i Q^r_i(s, a~pi)."""
    qc_mean: float
    """Batch mean of Q^c(s, a~pi), clamped at >= 0."""
    cost_signal: float
    """The measured cost fed to eq. 15 and 17, on Q^c's scale (SacConfig.multiplier_signal): the
    recent episodes' mean cost converted, or a mean Q^c."""
    entropy: float
    """Batch mean of -log pi(a|s), a ~ pi."""


class SacLagrangian:
    """The learner of all four variants: actor, twin reward critics, cost critic, targets,
    optimisers, alpha and the multiplier. Deterministic given `torch.manual_seed` (construction
    and every `update` draw from torch's global generator)."""

    def __init__(self, obs_dim: int, act_dim: int, config: SacConfig) -> None:
        self.obs_dim = obs_dim
        self.act_dim = act_dim
        self.config = config
        hidden = config.hidden_sizes
        self.actor = SquashedGaussianActor(obs_dim, act_dim, hidden)
        self.q_r = Critic(obs_dim, act_dim, hidden, n_members=2)
        self.q_c = Critic(obs_dim, act_dim, hidden, n_members=1)
        self.q_r_target = copy.deepcopy(self.q_r).requires_grad_(False)
        self.q_c_target = copy.deepcopy(self.q_c).requires_grad_(False)
        self.alpha = torch.tensor(config.alpha_init, requires_grad=True)
        self.uses_multiplier = config.variant in MULTIPLIER_VARIANTS
        self.multiplier = DampedLagrangeMultiplier(
            cost_limit=config.qc_limit,
            k_d=config.k_d if config.variant is Variant.TSSAC else 0.0,
            beta_init=config.beta_init if self.uses_multiplier else 0.0,
            lr=config.beta_lr,
            clamp_effective=config.clamp_effective,
            upper=config.multiplier_max,
        )
        self._actor_params: list[torch.Tensor] = list(self.actor.parameters())
        # WCSAC's variance critic (SacConfig.cost_cvar_level), made after everything else so that the learner
        # without it draws the same initial weights.
        self.q_c_var: Critic | None = None
        self.q_c_var_target: Critic | None = None
        if config.cost_cvar_level is not None:
            self.q_c_var = Critic(obs_dim, act_dim, hidden, n_members=1)
            self.q_c_var_target = copy.deepcopy(self.q_c_var).requires_grad_(False)
        variance = [] if self.q_c_var is None else [self.q_c_var]
        variance_target = [] if self.q_c_var_target is None else [self.q_c_var_target]
        self._critic_params: list[torch.Tensor] = [
            p for net in (self.q_r, self.q_c, *variance) for p in net.parameters()
        ]
        self._targets: list[torch.Tensor] = [
            p for net in (self.q_r_target, self.q_c_target, *variance_target) for p in net.parameters()
        ]
        self._onlines: list[torch.Tensor] = list(self._critic_params)
        self.reset_optimisers()

    def reset_optimisers(self) -> None:
        """Fresh Adam optimisers (no moments) for the actor, the critics and alpha."""
        # One optimiser for all three critics: Adam is elementwise, so this equals one per critic
        # with the summed loss, and costs one backward pass and one step.
        self.actor_optim = fast_adam(self._actor_params, self.config.lr)
        self.critic_optim = fast_adam(self._critic_params, self.config.lr)
        self.alpha_optim = fast_adam([self.alpha], self.config.lr)

    def networks(self) -> dict[str, nn.Module]:
        """The networks by name, as they appear in `state_dict` and `transfer`."""
        nets: dict[str, nn.Module] = {
            "actor": self.actor,
            "q_r": self.q_r,
            "q_c": self.q_c,
            "q_r_target": self.q_r_target,
            "q_c_target": self.q_c_target,
        }
        if self.q_c_var is not None and self.q_c_var_target is not None:
            nets.update(q_c_var=self.q_c_var, q_c_var_target=self.q_c_var_target)
        return nets

    @torch.no_grad()
    def act(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        """Actions in [-1, 1]: obs (n, obs_dim) -> (n, act_dim), or (obs_dim,) -> (act_dim,)."""
        obs_t = torch.as_tensor(obs, dtype=torch.float32)
        action, _ = self.actor(obs_t.unsqueeze(0) if obs_t.ndim == 1 else obs_t, deterministic)
        return action.squeeze(0).numpy() if obs_t.ndim == 1 else action.numpy()

    def update(
        self, batch: ReplaySamples, recent: ReplaySamples | None = None, episode_cost: float | None = None
    ) -> UpdateStats:
        """One gradient step of every part (Algorithm 1, line 13).

        What the multiplier (eq. 15, 17) compares with C (see SacConfig.multiplier_signal):
        ``episode_cost``, the mean measured cost per recent episode, if given; else the mean Q^c of
        the current policy on ``recent`` (SacConfig.multiplier_window), or on ``batch`` without it.
        """
        cfg = self.config
        obs, actions, rewards, costs, next_obs, terminated = batch
        if cfg.variant is Variant.SAC_PENALTY:
            rewards = rewards + cfg.penalty * costs
        alpha = self.alpha.detach().clone()  # the value used below, kept for the stats

        # Eq. 13, targets: soft value with the min of the twin target critics; no entropy in the cost.
        with torch.no_grad():
            next_actions, next_log_pi = self.actor(next_obs)
            next_q_r = self.q_r_target(next_obs, next_actions)
            next_v_r = losses.soft_value(next_q_r, next_log_pi, alpha)
            y_r = losses.critic_target(rewards, terminated, next_v_r, cfg.gamma)
            # A cost-to-go is never negative (eq. 11 costs are 0 or 1): clamp the bootstrap so that the
            # critic's extrapolation below 0 does not feed on itself.
            next_v_c = self.q_c_target(next_obs, next_actions)[0].clamp(min=0.0)
            y_c = losses.critic_target(costs, terminated, next_v_c, cfg.gamma)

        # Eq. 13, critic losses: one backward pass and one Adam step for the three critics.
        q_r_loss = losses.critic_loss(self.q_r(obs, actions), y_r)
        q_c_sa = self.q_c(obs, actions)
        q_c_loss = losses.critic_loss(q_c_sa, y_c)
        if self.q_c_var is not None and self.q_c_var_target is not None:  # WCSAC's variance critic, same step
            with torch.no_grad():
                next_var = cost_variance(self.q_c_var_target, next_obs, next_actions)
                y_var = losses.cost_variance_target(costs, terminated, next_v_c, next_var, q_c_sa[0], cfg.gamma)
            q_c_loss = q_c_loss + losses.variance_loss(cost_variance(self.q_c_var, obs, actions), y_var)
        self.critic_optim.zero_grad()
        (q_r_loss + q_c_loss).backward()
        self.critic_optim.step()

        # The policy's Q values at its own actions, the cost-to-go that eq. 4's g(pi) constrains (WCSAC's
        # saclag.py uses the replayed actions instead). Without a multiplier (SAC, SAC_PENALTY) Q^c is only
        # measured: no graph, no backward pass.
        pi_actions, log_pi = self.actor(obs)
        q_r_pi = self.q_r(obs, pi_actions)
        with torch.set_grad_enabled(self.uses_multiplier):
            q_c_pi = self.q_c(obs, pi_actions)[0]
        qc_mean = q_c_pi.detach().clamp(min=0.0).mean()
        cost_term = q_c_pi  # what the multiplier weighs in the actor loss: Q^c, or its CVaR (cost_cvar_level)
        if self.q_c_var is not None and cfg.cost_cvar_level is not None:
            with torch.set_grad_enabled(self.uses_multiplier):
                var_pi = cost_variance(self.q_c_var, obs, pi_actions)
                cost_term = losses.cost_cvar(q_c_pi, var_pi, cfg.cost_cvar_level)

        # What eq. 15 and 17 compare with C, on Q^c's scale (SacConfig.multiplier_signal): the recent episodes'
        # measured cost, else the mean Q^c of the current policy on the recent transitions, else on the batch.
        if episode_cost is not None:
            measured = cfg.cost_on_qc_scale(episode_cost)
        elif recent is not None:
            with torch.no_grad():
                measured = self.q_c(recent.observations, self.actor(recent.observations)[0])[0].clamp(min=0.0).mean()
        else:
            measured = qc_mean

        # Eq. 17, the damping xi = k_d (C - measured), and the multiplier of Q^c in the actor loss: beta - xi
        # (eq. 16; k_d = 0 for SAC_LAG: beta, eq. 12), 0 without a multiplier.
        beta = self.multiplier.beta
        if self.uses_multiplier:
            xi, multiplier = self.multiplier.damping(measured), self.multiplier.effective(measured)
        else:
            xi, multiplier = torch.zeros_like(measured), torch.zeros_like(measured)

        # Eq. 12 / 16, the actor loss, and eq. 14, alpha's loss (log_pi a constant there): one backward pass for
        # both (they share no parameter: the actor loss uses a detached alpha); inputs= keeps the critics' weights
        # out of it. Alpha is projected onto >= 0 after its step (SacConfig.alpha_init).
        actor_loss = losses.actor_loss(log_pi, q_r_pi, cost_term, alpha, multiplier)
        alpha_loss = losses.alpha_loss(self.alpha, log_pi, cfg.target_entropy)
        self.actor_optim.zero_grad()
        self.alpha_optim.zero_grad()
        torch.autograd.backward([actor_loss, alpha_loss], inputs=[*self._actor_params, self.alpha])
        self.actor_optim.step()
        self.alpha_optim.step()
        with torch.no_grad():
            self.alpha.clamp_(min=0.0)

        # Eq. 15, the multiplier's projected step (DampedLagrangeMultiplier.update), then Polyak averaging of the
        # targets: target <- polyak * target + (1 - polyak) * online.
        beta_loss = self.multiplier.update(measured) if self.uses_multiplier else torch.zeros_like(measured)
        with torch.no_grad():
            torch._foreach_lerp_(self._targets, self._onlines, 1.0 - cfg.polyak)

        scalars = torch.stack(
            [
                q_r_loss.detach(),
                q_c_loss.detach(),
                actor_loss.detach(),
                alpha_loss.detach(),
                beta_loss,
                alpha,
                beta,
                xi,
                multiplier,
                q_r_pi.detach().min(dim=0).values.mean(),
                qc_mean,
                measured,
                -log_pi.detach().mean(),
            ]
        ).tolist()  # one synchronisation for all statistics
        return UpdateStats(*scalars)

    def state_dict(self) -> dict[str, Any]:
        """All needed to resume: networks, targets, optimiser states, alpha, the multiplier.

        As with torch's own `state_dict`, the tensors share storage with the live learner: save it
        (`torch.save`) or `copy.deepcopy` it to keep a snapshot while training goes on.
        """
        state: dict[str, Any] = {name: net.state_dict() for name, net in self.networks().items()}
        state.update(
            actor_optim=self.actor_optim.state_dict(),
            critic_optim=self.critic_optim.state_dict(),
            alpha=self.alpha.detach().clone(),
            alpha_optim=self.alpha_optim.state_dict(),
            multiplier=self.multiplier.state_dict(),
            variant=self.config.variant.value,
        )
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what `state_dict` returned (same sizes; a different variant is logged)."""
        if state.get("variant") != self.config.variant.value:
            logger.warning(
                "loading a %s checkpoint into a %s learner",
                state.get("variant"),
                self.config.variant.value,
            )
        for name, net in self.networks().items():
            net.load_state_dict(state[name])
        # Optimiser.load_state_dict keeps the given moment tensors (no copy); copy them so that
        # two learners loaded from one in-memory state never share (and update) the same moments.
        load_optimiser(self.actor_optim, copy.deepcopy(state["actor_optim"]))
        load_optimiser(self.critic_optim, copy.deepcopy(state["critic_optim"]))
        with torch.no_grad():
            self.alpha.copy_(state["alpha"])
        load_optimiser(self.alpha_optim, copy.deepcopy(state["alpha_optim"]))
        self.multiplier.load_state_dict(state["multiplier"])


TRANSFERRED_NETWORKS = ("actor", "q_r", "q_c", "q_r_target", "q_c_target")
"""What `transfer` copies: all network weights. Everything else is reset."""
VARIANCE_NETWORKS = ("q_c_var", "q_c_var_target")
"""Also copied when both learners have them (SacConfig.cost_cvar_level); else the target's stay as they are."""
VARIANCE_FLOOR = 1e-6
"""Added to the variance critic's softplus, so that sqrt(V^c) has a finite gradient everywhere."""


def cost_variance(net: nn.Module, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """V^c(s, a) > 0 of WCSAC's variance critic, (batch,): the network's output through a softplus."""
    return nn.functional.softplus(net(obs, actions)[0]) + VARIANCE_FLOOR


def transfer(target: SacLagrangian, source_state: dict[str, Any]) -> list[str]:
    """TSSAC's parameter transfer N_k -> N_k+1 (Algorithm 1, lines 17 and 19).

    Copied from `source_state` (a `SacLagrangian.state_dict()`): the weights of the actor, the
    reward critics, the cost critic and their targets (TRANSFERRED_NETWORKS), and the variance critic and its
    target when both learners have one (VARIANCE_NETWORKS).
    Reset to `target.config`: the optimiser states (fresh Adam moments), alpha (alpha_init) and
    beta (beta_init, with a fresh optimiser), since the new task has its own entropy and cost
    balance. Returns the names of the copied tensors, "<network>.<parameter>".
    """
    copied: list[str] = []
    nets = target.networks()
    names = [*TRANSFERRED_NETWORKS, *(n for n in VARIANCE_NETWORKS if n in nets and n in source_state)]
    for name in names:
        nets[name].load_state_dict(source_state[name])
        copied += [f"{name}.{key}" for key in source_state[name]]
    with torch.no_grad():
        target.alpha.fill_(target.config.alpha_init)
    target.reset_optimisers()
    target.multiplier.reset()
    logger.info("transferred %d tensors; optimisers, alpha and beta reset", len(copied))
    return copied
