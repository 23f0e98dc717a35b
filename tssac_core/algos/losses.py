"""The losses of SAC-Lagrangian and TSSAC (paper eq. 12-17) as small pure functions.

Shapes: per-sample tensors are (batch,); critic outputs of an ensemble are (n_members, batch).
Symbols follow the paper: log_pi, q_r (reward critic), q_c (cost critic), alpha, beta, xi,
cost_limit (C, already converted to the scale of q_c, see `lagrange.qc_limit`).
"""

from __future__ import annotations

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
