"""The losses of SAC-Lagrangian and TSSAC (paper eq. 12-17) as small pure functions.

Shapes: per-sample tensors are (batch,); critic outputs of an ensemble are (n_members, batch).
Symbols follow the paper: log_pi, q_r (reward critic), q_c (cost critic), alpha, beta, xi,
cost_limit (C, already converted to the scale of q_c, see `lagrange.qc_limit`).
"""

from __future__ import annotations

from statistics import NormalDist

import torch


def soft_value(next_q_r: torch.Tensor, next_log_pi: torch.Tensor, alpha: torch.Tensor) -> torch.Tensor:
    """Eq. 13's V(s') = min_i Q^r_i(s', a') - alpha log pi(a'|s'), a' ~ pi(s'); twin critics."""
    return next_q_r.min(dim=-2).values - alpha * next_log_pi


def critic_target(
    reward: torch.Tensor, terminated: torch.Tensor, next_value: torch.Tensor, gamma: float
) -> torch.Tensor:
    """Eq. 13's regression target r + gamma (1 - terminated) V(s').

    Only termination stops bootstrapping; a truncated transition (episode cap) still bootstraps.
    For the cost critic, reward is the cost c and V(s') = Q^c(s', a') with no entropy term.
    """
    return reward + gamma * (1.0 - terminated) * next_value


def critic_loss(q: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Eq. 13: J_Q = E[1/2 (Q(s, a) - target)^2], summed over the ensemble (members axis)."""
    return 0.5 * (q - target).square().mean(dim=-1).sum(dim=-1)


def actor_loss(
    log_pi: torch.Tensor,
    q_r: torch.Tensor,
    q_c: torch.Tensor,
    alpha: torch.Tensor,
    multiplier: torch.Tensor,
) -> torch.Tensor:
    """Eq. 12 / 16: J_pi = E[alpha log pi - min_i Q^r_i + m Q^c], m = beta or beta - xi."""
    return (alpha * log_pi - q_r.min(dim=-2).values + multiplier * q_c).mean(dim=-1)


def alpha_loss(alpha: torch.Tensor, log_pi: torch.Tensor, target_entropy: float) -> torch.Tensor:
    """Eq. 14: J(alpha) = E[-alpha log pi - alpha H0]; log_pi is treated as a constant."""
    return alpha * (-log_pi.detach() - target_entropy).mean(dim=-1)


def multiplier_loss(beta: torch.Tensor, qc_mean: torch.Tensor, cost_limit: float) -> torch.Tensor:
    """Eq. 15: J(beta) = beta (C - E[Q^c]); qc_mean is treated as a constant."""
    return beta * (cost_limit - qc_mean.detach())


def damping(qc_mean: torch.Tensor, cost_limit: float, k_d: float) -> torch.Tensor:
    """Eq. 17: xi = k_d (C - E[Q^c]), with the batch mean of Q^c treated as a constant."""
    return k_d * (cost_limit - qc_mean.detach())


# --- Worst-case cost (WCSAC, Yang et al. 2021): a Gaussian cost-to-go, N(Q^c, V^c), and its CVaR -----------------


def cost_variance_target(
    cost: torch.Tensor,
    terminated: torch.Tensor,
    next_q_c: torch.Tensor,
    next_var_c: torch.Tensor,
    q_c: torch.Tensor,
    gamma: float,
) -> torch.Tensor:
    """WCSAC's Bellman target of the cost-to-go's variance, clamped at >= 0:
    V^c(s, a) = c^2 + 2 gamma c Q^c(s', a') + gamma^2 V^c(s', a') + gamma^2 Q^c(s', a')^2 - Q^c(s, a)^2,
    the next-state terms dropped on termination. A deterministic chain gets 0."""
    g = gamma * (1.0 - terminated)
    target = cost.square() + 2.0 * g * cost * next_q_c + g.square() * (next_var_c + next_q_c.square()) - q_c.square()
    return target.clamp(min=0.0)


def variance_loss(var: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """The variance part of the squared 2-Wasserstein distance between N(m, var) and N(m', target), WCSAC's loss
    of the variance critic: E[var + target - 2 sqrt(var) sqrt(target)] (target a constant; var > 0, so the
    gradient stays finite where the target is 0)."""
    return (var + target - 2.0 * var.sqrt() * target.detach().sqrt()).mean(dim=-1)


def cvar_coefficient(level: float) -> float:
    """phi(Phi^-1(level)) / level: the CVaR at risk level ``level`` of a Gaussian is its mean plus this many
    standard deviations (the mean of its worst ``level`` share); 0 at level 1."""
    if level >= 1.0:
        return 0.0
    normal = NormalDist()
    return normal.pdf(normal.inv_cdf(level)) / level


def cost_cvar(q_c: torch.Tensor, var_c: torch.Tensor, level: float) -> torch.Tensor:
    """WCSAC's worst-case cost: CVaR_level of N(Q^c, V^c) = Q^c + phi(Phi^-1(level)) / level * sqrt(V^c)."""
    return q_c + cvar_coefficient(level) * var_c.sqrt()
