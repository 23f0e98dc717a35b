"""Generalised advantage estimation (Schulman et al. 2016, "High-Dimensional Continuous Control Using
Generalized Advantage Estimation", eq. 16) for batched rollouts of shape (T, N): T decisions of N
worlds that reset themselves, so that episodes end, and new ones start, inside the rollout.

Used for rewards and for costs alike (PPO, PPO-Lagrangian and CPO need cost advantages too).
"""

from __future__ import annotations

import torch


def gae(
    rewards: torch.Tensor,
    values: torch.Tensor,
    next_values: torch.Tensor,
    terminated: torch.Tensor,
    ended: torch.Tensor,
    gamma: float,
    lam: float,
) -> tuple[torch.Tensor, torch.Tensor]:
    """GAE(gamma, lambda), Schulman et al. 2016 eq. 16, with episode ends inside the rollout.

    Every argument is (T, N); step t of world n went s_t -> s'_t with reward (or cost) r_t:

        values[t]       V(s_t)
        next_values[t]  V(s'_t), s'_t the observation after the step *before* any reset (for a step
                        that did not end its episode s'_t = s_{t+1}; for the last step of the rollout
                        it is the bootstrap state)
        terminated[t]   s'_t is terminal: no future, V(s'_t) is not used
        ended[t]        the episode ended at this step (terminated or truncated): the advantage trace
                        stops here, since s_{t+1} belongs to a new episode

        delta_t = r_t + gamma (1 - terminated_t) V(s'_t) - V(s_t)
        A_t     = delta_t + gamma lam (1 - ended_t) A_{t+1},   A_T = 0
        R_t     = A_t + V(s_t)                                  (the value networks' target)

    A truncated episode (the cap, or any end the caller chooses to bootstrap through) is therefore
    ended but not terminated: its last delta bootstraps from the value of its final observation.
    Returns (advantages, returns), both (T, N), in the dtype of ``rewards``.
    """
    if not (rewards.shape == values.shape == next_values.shape == terminated.shape == ended.shape):
        raise ValueError(
            "gae: rewards, values, next_values, terminated and ended must have one shape (T, N), got "
            f"{[tuple(x.shape) for x in (rewards, values, next_values, terminated, ended)]}"
        )
    dtype = rewards.dtype
    not_terminal = 1.0 - terminated.to(dtype)
    not_ended = 1.0 - ended.to(dtype)
    deltas = rewards + gamma * not_terminal * next_values.to(dtype) - values.to(dtype)
    advantages = torch.zeros_like(deltas)
    running = torch.zeros_like(deltas[0])
    for t in range(deltas.shape[0] - 1, -1, -1):
        running = deltas[t] + gamma * lam * not_ended[t] * running
        advantages[t] = running
    return advantages, advantages + values.to(dtype)
