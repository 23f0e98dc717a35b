"""Evaluation statistics with uncertainty and tails (DESIGN.md section 6, "Evaluation statistics").

Pure functions over numpy arrays; nothing here flies a mission.

- Success: k of n missions with the 95% Wilson score interval (Wilson 1927), which stays inside [0, 1] and
  is not degenerate at k = 0 or k = n as the normal approximation is.
- Mean hazard cost per UAV: the mean over UAV-missions, with a 95% percentile bootstrap over *missions*
  (Efron and Tibshirani 1993, ch. 13): whole missions are resampled, each keeping its three UAVs together,
  because the three costs of one mission share a layout and are not independent. 2,000 resamples from a
  fixed seed, so a figure is the same every time it is computed.
- Tail per role: the fraction of UAV-missions within the cost limit C, the worst UAV-mission cost, and the
  CVaR at 95%: the mean of the worst 5% of UAV-mission costs (the worst ceil(0.05 n) of them; Rockafellar
  and Uryasev 2000, for a sample).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tssac_core.common.evaluation_record import EvaluationRecord, RoleFigures, WorstMission

Z_95 = 1.959963984540054
"""The standard normal's 97.5% quantile: a two-sided 95% interval."""
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 20261126
"""Fixed, so that an interval is a function of the data alone."""
CVAR_LEVEL = 0.95


@dataclass(frozen=True)
class Interval:
    """An estimate with its 95% interval."""

    value: float
    low: float
    high: float

    def as_dict(self) -> dict[str, float]:
        return {"value": self.value, "low": self.low, "high": self.high}


def wilson_interval(k: int, n: int, z: float = Z_95) -> Interval:
    """Success k of n with the Wilson score interval:
    (p + z^2/2n +- z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n), p = k/n."""
    if n <= 0 or not 0 <= k <= n:
        raise ValueError(f"need 0 <= k <= n and n > 0, got k={k}, n={n}")
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1.0 - p) / n + z * z / (4 * n * n)) / denom
    # At k = 0 (k = n) the exact bound is 0 (1); the formula gives it up to rounding.
    low = 0.0 if k == 0 else max(0.0, centre - half)
    high = 1.0 if k == n else min(1.0, centre + half)
    return Interval(p, low, high)


def bootstrap_mean_interval(
    cost: np.ndarray, resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED, level: float = 0.95
) -> Interval:
    """Mean of ``cost`` over all its entries, with a percentile bootstrap interval over its rows.

    ``cost`` is (M,) (one value per mission) or (M, U) (missions x UAVs): a resample draws M missions with
    replacement and keeps each mission's U values together. The mean of a resample is the mean over its
    M x U entries.
    """
    c = np.asarray(cost, dtype=np.float64)
    if c.ndim == 1:
        c = c[:, None]
    m = c.shape[0]
    if m == 0 or c.size == 0:
        raise ValueError("bootstrap_mean_interval: no missions")
    per_mission = c.mean(axis=1)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, m, size=(resamples, m))
    means = per_mission[idx].mean(axis=1)
    tail = (1.0 - level) / 2.0
    low, high = np.quantile(means, [tail, 1.0 - tail])
    return Interval(float(per_mission.mean()), float(low), float(high))


def cvar(values: np.ndarray, level: float = CVAR_LEVEL) -> float:
    """Mean of the worst (largest) ceil((1 - level) n) values: the sample CVaR at ``level``."""
    v = np.sort(np.asarray(values, dtype=np.float64).ravel())
    if v.size == 0:
        raise ValueError("cvar: no values")
    k = max(1, math.ceil(round((1.0 - level) * v.size, 9)))
    return float(v[-k:].mean())


def within_fraction(values: np.ndarray, limit: float) -> float:
    """The fraction of values <= limit."""
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size == 0:
        raise ValueError("within_fraction: no values")
    return float((v <= limit).mean())


def tail_figures(cost: np.ndarray, limit: float) -> RoleFigures:
    """One role's tail over its UAV-missions: within the limit, the worst cost, CVaR_0.95."""
    return RoleFigures(
        within_cost_limit=within_fraction(cost, limit), max_cost=float(np.max(cost)), cvar95_cost=cvar(cost)
    )


def worst_missions(cost: np.ndarray, seeds: Sequence[int], roles: Sequence[str], count: int = 10) -> list[WorstMission]:
    """The ``count`` costliest UAV-missions (cost > 0), worst first: mission index, its layout seed, role, cost."""
    c = np.asarray(cost, dtype=np.float64)
    order = np.argsort(-c, axis=None, kind="stable")[:count]
    rows = []
    for flat in order:
        i, j = (int(k) for k in np.unravel_index(int(flat), c.shape))
        if c[i, j] <= 0:
            break
        rows.append(WorstMission(mission=i, seed=int(seeds[i]), role=roles[j], cost=float(c[i, j])))
    return rows


def pooled_record(
    success: np.ndarray,
    cost: np.ndarray,
    limit: float,
    roles: Sequence[str],
    seeds: Sequence[int],
    worst: int = 10,
    time_s: Sequence[float] | None = None,
) -> EvaluationRecord:
    """The figures of M missions (``success`` (M,), ``cost`` (M, 3) per UAV, ``time_s`` (M,) each one's simulated time
    if known) with their intervals, every role's tail and the costliest UAV-missions, as ``mavlink_bridge.fly.pool``
    gives them for campaigns flown apart."""
    s = np.asarray(success, dtype=bool)
    c = np.asarray(cost, dtype=np.float64)
    rate = wilson_interval(int(s.sum()), int(s.size))
    mean = bootstrap_mean_interval(c)
    return EvaluationRecord(
        success_rate=float(s.mean()),
        success_interval95=(rate.low, rate.high),
        mean_cost=float(c.mean()),
        mean_cost_interval95=(mean.low, mean.high),
        episodes=int(s.size),
        mean_mission_time_s=float(np.mean(time_s)) if time_s else None,
        roles={role: tail_figures(c[:, j], limit) for j, role in enumerate(roles)},
        worst_missions=worst_missions(c, seeds, roles, worst),
    )
