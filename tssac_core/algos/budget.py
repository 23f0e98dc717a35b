"""The per-episode cost budget C on the scale of the discounted cost-to-go Q^c (numpy-free, torch-free)."""

from __future__ import annotations


def qc_limit(cost_per_episode: float, gamma: float, episode_steps: int) -> float:
    """Convert a per-episode cost budget C into the scale of Q^c: C (1 - gamma^T) / ((1 - gamma) T).

    Q^c(s, a) estimates a discounted cost-to-go, while the paper's threshold C (Table 3: 3) is an
    undiscounted sum of costs per episode of T steps. Spending the budget uniformly, C / T per step,
    gives the discounted sum  sum_{t<T} gamma^t C / T = C (1 - gamma^T) / ((1 - gamma) T), the value
    the constraint compares Q^c with. The same conversion as WCSAC's `saclag.py` (TU Delft,
    https://github.com/AlgTUDelft/WCSAC). It is approximate: costs are not uniform along an
    episode, and Q^c is a cost-to-go from every state of the buffer, not from the start state.
    """
    if not 0.0 <= gamma < 1.0:
        raise ValueError(f"gamma must be in [0, 1), got {gamma}")
    if episode_steps < 1:
        raise ValueError(f"episode_steps must be >= 1, got {episode_steps}")
    return cost_per_episode * (1.0 - gamma**episode_steps) / ((1.0 - gamma) * episode_steps)
