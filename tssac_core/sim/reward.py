"""The reward (eq. 10 with Table 2), with the two terms the paper lacks, for all roles at once.

    r = k1 r_done + k2 r_approach + k3 r_step + r_hold + r_out

    r_done     = +10 on the step the role's task is first completed (eq. 9): decoy first enters its
                 ring, detect identifies the target, strike hits it. Once per episode.
    r_approach = d_{t-1} - d_t in km, where d is the length of the way to the role's *zone* around the
                 SAM (0 inside it): the straight-line distance to the zone plus the detour that radars
                 in the way force (:class:`tssac_core.sim.routes.RouteMap`; deviation, docs/decisions.md).
                 With a free line of sight this is the paper's distance to the SAM minus a constant, so
                 the term is the paper's; inside the zone it is 0, so nothing pulls the decoy through
                 its ring towards the SAM (where it would leave its zone). The detour removes the trap
                 of the straight-line term: in front of a wall of radars every way around first
                 *increases* the straight-line distance, so that term rewards stalling there.
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
from functools import cached_property

import numpy as np

from tssac_core.sim.routes import RouteConfig
from tssac_core.sim.world import KM, StepResult, constant_operand


@dataclass(frozen=True)
class _Weights:
    """A config's weights as numpy operands: each flag's term as a table (flag 0 or 1 -> its value) and the
    constants as 0-d arrays. The tables hold ``weight * 0.0`` and ``weight * 1.0``, the very floats that
    multiplying the flags (as 0.0 and 1.0) by the weight gives (-0.0 for a negative weight's 0), looked up
    in one call instead of a cast and a product; the sums are those of eq. 10, in its order."""

    done: np.ndarray
    k2: np.ndarray
    step: np.ndarray
    hold: np.ndarray
    out_of_area: np.ndarray

    @staticmethod
    def of(cfg: RewardConfig) -> _Weights:
        def table(weight: float) -> np.ndarray:
            return np.multiply(np.array([0.0, 1.0]), weight)

        return _Weights(
            table(cfg.k1 * cfg.success),
            constant_operand(cfg.k2),
            constant_operand(cfg.k3 * cfg.step),
            table(cfg.hold),
            table(cfg.out_of_area),
        )


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
    around_radars: bool = True
    """r_approach measures the way around the radars (True) or the straight line (False, the paper)."""
    route: RouteConfig = RouteConfig()
    """How the way around the radars is measured (the margin kept from them, the cost of crossing one)."""

    @cached_property
    def operands(self) -> _Weights:
        """The weights as :func:`reward` uses them, made on first use and kept in the instance (not a field:
        equality, hashing and ``asdict`` ignore it)."""
        return _Weights.of(self)


def reward(
    result: StepResult,
    moving: np.ndarray,
    cfg: RewardConfig = RewardConfig(),
    detour_prev_m: np.ndarray | float = 0.0,
    detour_m: np.ndarray | float = 0.0,
    vehicle: int | None = None,
) -> np.ndarray:
    """Reward of every vehicle for one step, (N, 3), or of vehicle index ``vehicle`` only, (N,).

    ``moving`` (N, 3) marks vehicles that took the step. ``detour_prev_m`` and ``detour_m``: the detour
    before and after the step (:meth:`tssac_core.sim.routes.RouteMap.detour_m`; 0, the default, measures the
    straight line as the paper), of every vehicle (N, 3) or, with ``vehicle``, of that one (N,).
    """
    cols = slice(None) if vehicle is None else vehicle  # a learner's reward needs its own column only
    w = cfg.operands
    before = result.zone_dist_prev_m[:, cols] + detour_prev_m
    after = result.zone_dist_m[:, cols] + detour_m
    approach_km = (before - after) / _KM
    # Every term is built afresh: an in-place update of a one-element array (a learner's column at N = 1)
    # takes numpy's slow path (see :class:`tssac_core.sim.world.World`).
    r = (
        w.done.take(result.task_completed[:, cols].astype(np.intp))
        + w.k2 * approach_km
        + w.step
        + w.hold.take(result.in_zone[:, cols].astype(np.intp))
        + w.out_of_area.take(result.out_of_area[:, cols].astype(np.intp))
    )
    return np.where(moving[:, cols], r, _ZERO)


_KM, _ZERO = constant_operand(KM), constant_operand(0.0)
