"""The reward (eq. 10 with Table 2), with the two terms the paper lacks, for all roles at once.

    r = k1 r_done + k2 r_approach + k3 r_step + r_hold + r_out

    r_done     = +10 on the step the role's task is first completed (eq. 9): decoy first enters its
                 ring, detect identifies the target, strike hits it. Once per episode.
    r_approach = d_{t-1} - d_t in km, where d is the distance to the role's *zone* around the SAM
                 (0 inside it). Outside the zone this equals the paper's distance to the SAM minus a
                 constant, so the term is the paper's; inside it is 0, so nothing pulls the decoy
                 through its ring towards the SAM (where it would leave its zone).
    r_step     = -0.1 per step.
    r_hold     = +0.1 per step while the role holds its zone (deviation, DESIGN.md: a fixed-wing UAV
                 must be taught to loiter in its zone, not only to reach it). It cancels r_step there:
                 holding costs nothing, anything else costs 0.1 per step, and ending the episode by a
                 hit is neither better nor worse than holding on, so no role profits from delaying it.
    r_out      = -20 once, when the UAV leaves the area (deviation: without it, leaving would be a way
                 out of the step penalty; -20 = -r_done plus the step penalty's value for ever,
                 -0.1 / (1 - gamma)).

See docs/decisions.md for the reasoning.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tssac_core.world import KM, StepResult


@dataclass(frozen=True)
class RewardConfig:
    """Table 2 values and weights (Table 3: k = (1, 1, 1)), plus our two added terms."""

    success: float = 10.0
    """r_done."""
    step: float = -0.1
    """r_step."""
    hold: float = 0.1
    """r_hold per step in the zone (not in the paper)."""
    out_of_area: float = -20.0
    """r_out, once on leaving the area (not in the paper)."""
    k1: float = 1.0
    k2: float = 1.0
    k3: float = 1.0


def reward(result: StepResult, moving: np.ndarray, cfg: RewardConfig = RewardConfig()) -> np.ndarray:
    """Reward of every vehicle for one step, (N, 3); ``moving`` marks vehicles that took the step."""
    approach_km = (result.zone_dist_prev_m - result.zone_dist_m) / KM
    r = (
        cfg.k1 * cfg.success * result.task_completed
        + cfg.k2 * approach_km
        + cfg.k3 * cfg.step
        + cfg.hold * result.in_zone
        + cfg.out_of_area * result.out_of_area
    )
    return np.where(moving, r, 0.0)
