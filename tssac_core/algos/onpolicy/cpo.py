"""CPO (Achiam et al. 2017, "Constrained Policy Optimization"), a baseline of the paper's comparison.

`Cpo.update` reads like the paper's Algorithm 1 / section 6.1: the gradients g of the reward
surrogate and b of the cost surrogate -> H^-1 g and H^-1 b by conjugate gradient on Fisher-vector
products of the KL -> the step of the dual problem (eq. 12-13) with its cases, or the recovery step
when no policy in the trust region satisfies the linearised constraint -> backtracking line search on
KL, cost and surrogate improvement -> value regression of V^r and V^c.

**The constraint value c.** CPO linearises J_C(pi') <= C around pi: c + b^T x <= 0, c = J_C(pi) - C.
Here J_C is the cost per episode (undiscounted, the scale of C, measured on the last finished
episodes) while the surrogate E[ratio A^c] whose gradient is b is a mean per decision; the change of an
episode's cost is about L times the change of that mean, for episodes of L decisions. So

    c = (J_C - C) / L

with L the mean length in decisions of the same episodes (the rescaling of Ray et al.'s
safety-starter-agents, which divides by the mean episode length; OmniSafe 0.5.0's CPO does not: its c is
EpCost - C per episode, beside cost advantages centred as here). A^c is centred but not scaled
(`ppo.normalised_advantages`), so that b^T x and c share units.
"""

from __future__ import annotations

import copy
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from tssac_core.algos.networks import SquashedGaussianActor
from tssac_core.algos.onpolicy.ppo import (
    CpoState,
    OnPolicyAlgo,
    OnPolicyBatch,
    OnPolicyConfig,
    OnPolicyStats,
    PpoState,
    as_batch_tensor,
    evaluate_values,
    fit_values,
    gaussian_kl,
    load_networks,
    networks_state,
    normalised_advantages,
    squashed_gaussian_log_prob,
    value_networks,
)

logger = logging.getLogger(__name__)

_EPS = 1e-8
_FLAT_COST_GRADIENT = 1e-8
"""b^T b below this: the cost surrogate is flat (safety-starter-agents' test)."""

INFEASIBLE, RECOVERABLE, FEASIBLE_ACTIVE, FEASIBLE_INTERIOR, NO_COST_GRADIENT = 0, 1, 2, 3, 4
"""CPO's cases, numbered as in safety-starter-agents: 0 no policy in the trust region satisfies the
linearised constraint (recovery step); 1 infeasible now, but part of the trust region satisfies it;
2 feasible now, the constraint cuts the trust region; 3 feasible, the whole trust region satisfies it;
4 the cost surrogate is flat (b = 0)."""


# --- pure functions -----------------------------------------------------------------------------


def conjugate_gradient(
    Avp: Callable[[torch.Tensor], torch.Tensor], b: torch.Tensor, iters: int, tol: float = 1e-10
) -> torch.Tensor:
    """Solve A x = b for symmetric positive-definite A given only x -> A x (Hestenes & Stiefel 1952;
    CPO section 6.1). Starts at x = 0; stops after ``iters`` iterations or once ||b - A x|| < tol."""
    x = torch.zeros_like(b)
    r = b.clone()
    p = b.clone()
    rr = r.dot(r)
    for _ in range(iters):
        if rr.sqrt() < tol:
            break
        Ap = Avp(p)
        alpha = rr / p.dot(Ap)
        x = x + alpha * p
        r = r - alpha * Ap
        rr_new = r.dot(r)
        p = r + (rr_new / rr) * p
        rr = rr_new
    return x


@dataclass(frozen=True)
class CpoStep:
    """The solution of CPO's approximate problem."""

    step: torch.Tensor
    """x: the parameter change, theta_new = theta + x (before the line search)."""
    case: int
    """INFEASIBLE, RECOVERABLE, FEASIBLE_ACTIVE, FEASIBLE_INTERIOR or NO_COST_GRADIENT."""
    lam: float
    """Dual variable of the trust region (NaN for the recovery step)."""
    nu: float
    """Dual variable of the cost constraint."""


def cpo_step(
    g: torch.Tensor, b: torch.Tensor, Hinv_g: torch.Tensor, Hinv_b: torch.Tensor, c: float, max_kl: float
) -> CpoStep:
    """Achiam et al. 2017 eq. 12-13 (dual, Theorem 2 in the appendix) and the recovery of section 6.2:

        max_x g^T x   s.t.   c + b^T x <= 0,   1/2 x^T H x <= delta

    with q = g^T H^-1 g, r = g^T H^-1 b, s = b^T H^-1 b, A = q - r^2/s, B = 2 delta - c^2/s:
    - b = 0 (flat cost): the reward's trust-region step x = sqrt(2 delta / q) H^-1 g if c < 0,
      else no step (nothing is known that lowers the cost);
    - c < 0, B < 0: the whole trust region is feasible: the same step;
    - B >= 0: x = (1/lam) H^-1 (g - nu b), nu = max(0, lam c + r) / s, lam the minimiser of the dual
          D_a(lam) = A/(2 lam) + lam B/2 - r c / s   on {lam > 0 : lam c + r > 0}  (constraint active)
          D_b(lam) = q/(2 lam) + lam delta           on {lam > 0 : lam c + r <= 0} (constraint slack)
      whose unconstrained minimisers sqrt(A/B) and sqrt(q/(2 delta)) are projected onto their sets;
    - c > 0, B < 0: infeasible: the recovery step x = -sqrt(2 delta / s) H^-1 b, which only lowers the cost.
    """
    q = g.dot(Hinv_g).item()
    r = g.dot(Hinv_b).item()
    s = b.dot(Hinv_b).item()
    delta = max_kl

    def reward_step() -> torch.Tensor:
        return math.sqrt(2.0 * delta / (q + _EPS)) * Hinv_g

    if b.dot(b).item() <= _FLAT_COST_GRADIENT or s <= _EPS:
        if c < 0.0:
            return CpoStep(reward_step(), NO_COST_GRADIENT, math.sqrt(q / (2.0 * delta)), 0.0)
        return CpoStep(torch.zeros_like(g), NO_COST_GRADIENT, math.nan, 0.0)
    B = _margin_b(c, s, delta)
    if c < 0.0 and B < 0.0:
        return CpoStep(reward_step(), FEASIBLE_INTERIOR, math.sqrt(q / (2.0 * delta)), 0.0)
    if B < 0.0:
        nu = math.sqrt(2.0 * delta / s)
        return CpoStep(-nu * Hinv_b, INFEASIBLE, math.nan, nu)

    lam, nu = dual_solution(q, r, s, c, delta)
    case = RECOVERABLE if c >= 0.0 else FEASIBLE_ACTIVE
    return CpoStep((Hinv_g - nu * Hinv_b) / lam, case, lam, nu)


def dual_solution(q: float, r: float, s: float, c: float, delta: float) -> tuple[float, float]:
    """(lam, nu) of :func:`cpo_step`'s cases 1 and 2 (B >= 0): lam the minimiser of the dual over the active and
    the slack set, nu = max(0, lam c + r) / s, so that the step (1/lam) H^-1 (g - nu b) has b^T x = -c when the
    constraint is active (g the gradient of the reward to raise, b of the cost)."""
    A = q - r * r / s
    B = _margin_b(c, s, delta)
    # The sets where the constraint is active (lam c + r > 0) and slack, as intervals of lam > 0.
    if c < 0.0:
        boundary = -r / c
        active, slack = (0.0, boundary), (boundary, math.inf)
    elif c > 0.0:
        boundary = -r / c
        active, slack = (boundary, math.inf), (0.0, boundary)
    else:  # c == 0: active iff r > 0, whatever lam
        active, slack = ((0.0, math.inf), (0.0, 0.0)) if r > 0.0 else ((0.0, 0.0), (0.0, math.inf))

    def dual_a(lam: float) -> float:
        return A / (2.0 * lam) + lam * B / 2.0 - r * c / s

    def dual_b(lam: float) -> float:
        return q / (2.0 * lam) + lam * delta

    candidates: list[tuple[float, float]] = []  # (dual value, lam)
    for (lo, hi), best, dual in (
        (active, math.sqrt(max(A, 0.0) / max(B, _EPS)), dual_a),
        (slack, math.sqrt(q / (2.0 * delta)), dual_b),
    ):
        lo = max(lo, 0.0)
        if hi <= lo:
            continue  # empty set
        lam = min(max(best, lo), hi)
        lam = max(lam, _EPS)
        candidates.append((dual(lam), lam))
    _, lam = min(candidates)
    return lam, max(0.0, lam * c + r) / s


def _margin_b(c: float, s: float, delta: float) -> float:
    """B = 2 delta - c^2 / s: >= 0 when the constraint's boundary meets the trust region (Achiam et al. 2017)."""
    return 2.0 * delta - c * c / s


def line_search_accepts(kl: float, surr_r_gain: float, surr_c_rise: float, c: float, max_kl: float, case: int) -> bool:
    """CPO's line-search test (Achiam et al. 2017 section 6.1; safety-starter-agents' conditions):
    KL <= delta, the cost surrogate rises by at most max(-c, 0), and, when the current policy is
    feasible (cases 2-4), the reward surrogate does not fall."""
    if not kl <= max_kl:  # also rejects NaN
        return False
    if not surr_c_rise <= max(-c, 0.0):
        return False
    return case < FEASIBLE_ACTIVE or surr_r_gain >= 0.0


def constraint_value(episode_cost: float, cost_limit: float, episode_length: float) -> float:
    """c = (J_C - C) / L: the constraint violation per decision (see the module docstring)."""
    return (episode_cost - cost_limit) / max(episode_length, 1.0)


# --- the learner ----------------------------------------------------------------------------------


def _flat_grad(y: torch.Tensor, params: list[nn.Parameter], **kwargs: Any) -> torch.Tensor:
    grads = torch.autograd.grad(y, params, **kwargs)
    return torch.cat([gr.reshape(-1) for gr in grads])


@torch.no_grad()
def _set_flat(params: list[nn.Parameter], flat: torch.Tensor) -> None:
    """Copy a flat vector into the parameters, in place (torch's vector_to_parameters rebinds .data
    to views of one vector instead)."""
    offset = 0
    for p in params:
        p.copy_(flat[offset : offset + p.numel()].view_as(p))
        offset += p.numel()


def fisher_vector_product(
    actor: SquashedGaussianActor, obs: torch.Tensor, damping: float
) -> Callable[[torch.Tensor], torch.Tensor]:
    """v -> (H + damping I) v, H the Hessian at the current parameters of the mean KL(pi_current || pi_theta)
    over ``obs``: the Fisher information matrix of CPO's trust region (Achiam et al. 2017 section 6.1).
    One double-backward graph serves every call (conjugate gradient calls it cg_iters times)."""
    params = list(actor.parameters())
    with torch.no_grad():
        mean_old, log_std_old = actor.mean_log_std(obs)
    mean, log_std = actor.mean_log_std(obs)
    kl = gaussian_kl(mean_old, log_std_old, mean, log_std).mean()
    grad_kl = _flat_grad(kl, params, create_graph=True)

    def fvp(v: torch.Tensor) -> torch.Tensor:
        return _flat_grad(grad_kl.dot(v), params, retain_graph=True) + damping * v

    return fvp


class Cpo:
    """CPO: actor, V^r, V^c and the value optimiser (the actor moves by natural-gradient steps).
    Deterministic given `torch.manual_seed`."""

    def __init__(self, obs_dim: int, act_dim: int, config: OnPolicyConfig) -> None:
        if config.algo is not OnPolicyAlgo.CPO:
            raise ValueError(f"Cpo runs cpo, got {config.algo.value}")
        self.obs_dim = obs_dim
        self.act_dim = act_dim
        self.config = config
        self.actor = SquashedGaussianActor(obs_dim, act_dim, config.hidden_sizes)
        self.v_r, self.v_c = value_networks(obs_dim, config.hidden_sizes)
        self.value_optim = torch.optim.Adam([*self.v_r.parameters(), *self.v_c.parameters()], lr=config.lr, eps=1e-5)
        self.uses_multiplier = False

    @torch.no_grad()
    def act(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        """Actions in [-1, 1]: obs (n, obs_dim) -> (n, act_dim)."""
        action, _ = self.actor(as_batch_tensor(obs), deterministic)
        return action.numpy()

    def update(self, batch: OnPolicyBatch, episode_cost: float, episode_length: float) -> OnPolicyStats:
        """One CPO policy step, then value regression.

        ``episode_cost``: the measured cost per episode J_C (the scale of C); ``episode_length``: the
        mean length in decisions of the same episodes (see the module docstring for c).
        """
        cfg = self.config
        c = constraint_value(episode_cost, cfg.cost_limit, episode_length)
        obs, actions, log_pi_old = batch.observations, batch.actions, batch.log_pi_old
        adv_r, adv_c = (
            normalised_advantages(batch.adv_r, batch.adv_c) if cfg.normalize_advantages else (batch.adv_r, batch.adv_c)
        )
        with torch.no_grad():
            v_r_mean, v_c_mean = (v.mean().item() for v in evaluate_values(self.v_r, self.v_c, obs))
            mean_old, log_std_old = self.actor.mean_log_std(obs)
        params = list(self.actor.parameters())

        def surrogates() -> tuple[torch.Tensor, torch.Tensor]:
            mean, log_std = self.actor.mean_log_std(obs)
            ratio = torch.exp(squashed_gaussian_log_prob(mean, log_std, actions) - log_pi_old)
            return (ratio * adv_r).mean(), (ratio * adv_c).mean()

        surr_r, surr_c = surrogates()
        g = _flat_grad(surr_r, params, retain_graph=True)
        b = _flat_grad(surr_c, params)
        surr_r_old, surr_c_old = surr_r.item(), surr_c.item()

        fvp = fisher_vector_product(self.actor, obs, cfg.damping)
        Hinv_g = conjugate_gradient(fvp, g, cfg.cg_iters, cfg.cg_tol)
        Hinv_b = conjugate_gradient(fvp, b, cfg.cg_iters, cfg.cg_tol)
        solution = cpo_step(g, b, Hinv_g, Hinv_b, c, cfg.max_kl)

        theta_old = torch.cat([p.detach().reshape(-1) for p in params])
        accepted, new_kl, new_surr_r = 0.0, 0.0, surr_r_old
        if solution.step.abs().sum().item() > 0.0:
            for k in range(cfg.backtrack_iters):
                fraction = cfg.backtrack_coef**k
                _set_flat(params, theta_old + fraction * solution.step)
                with torch.no_grad():
                    sr, sc = surrogates()
                    mean, log_std = self.actor.mean_log_std(obs)
                    step_kl = gaussian_kl(mean_old, log_std_old, mean, log_std).mean().item()
                if line_search_accepts(
                    step_kl, sr.item() - surr_r_old, sc.item() - surr_c_old, c, cfg.max_kl, solution.case
                ):
                    accepted, new_kl, new_surr_r = fraction, step_kl, sr.item()
                    break
            else:
                _set_flat(params, theta_old)
                logger.debug("cpo: line search found no acceptable step (case %d); policy unchanged", solution.case)
        logger.debug(
            "cpo: case %d, c %.4g, lam %.4g, nu %.4g, step fraction %.3g",
            solution.case,
            c,
            solution.lam,
            solution.nu,
            accepted,
        )

        v_r_loss, v_c_loss, value_steps = fit_values(self.v_r, self.v_c, self.value_optim, batch, cfg)
        return OnPolicyStats(
            policy_loss=-new_surr_r,
            v_r_loss=v_r_loss,
            v_c_loss=v_c_loss,
            multiplier_loss=math.nan,
            multiplier=math.nan,
            v_r_mean=v_r_mean,
            v_c_mean=v_c_mean,
            entropy=-log_pi_old.mean().item(),
            approx_kl=new_kl,
            policy_steps=int(accepted > 0.0),
            value_steps=value_steps,
            cpo_case=solution.case,
            step_fraction=accepted,
        )

    def state_dict(self) -> CpoState:
        """Networks and the value optimiser (share storage with the learner, like torch's)."""
        return {
            **networks_state(self.config.algo, self.actor, self.v_r, self.v_c),
            "value_optim": self.value_optim.state_dict(),
        }

    def load_state_dict(self, state: CpoState | PpoState) -> None:
        """Restore what `state_dict` returned."""
        load_networks(state, self.config.algo, self.actor, self.v_r, self.v_c)
        self.value_optim.load_state_dict(copy.deepcopy(state["value_optim"]))
