"""Measure how far an airframe's path lies from the monitor's prediction of a backup whose lead holds its course
(:func:`tssac_core.assurance.lagged_backups.held_rollout`): in JSBSim under the airframe's inner loop, and on the lag
model itself, from the states a backup is worst started from, in calm air (held leads are not offered in wind).

A run (:func:`fly_held`): the airframe holds a maximum-rate turn one way for ``ENTRY_HOLD_S`` (its bank settled), then
commands the other way for ``reversal_s`` (the middle of a reversal: the roll-out the model predicts worst); there
the backup starts. It flies straight (command 0) for ``held_after_s``, then holds the ground line through where it is
then along the course the model predicted there (:mod:`tssac_core.assurance.held_course`) until its lead ends, then
its maximum-rate turn for ``TURN_S``. The prediction is the monitor's: the held rollout, then the turn's samples and
the disk the rest stays in (:func:`~tssac_core.assurance.lagged_backups.turn_keep_out`). A run's residual is the
largest of: the distance from the predicted position at the same step over the lead and the turn's samples, and the
distance beyond the disk after them. The same backup flown on the lag model (the law steering the model) gives the
model's own residual, so that the bound holds in the batched world too. The fit's figure per speed is the largest of
its runs, both flights.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from sim_vehicles.dynamics.jsbsim_airframe import AirframeSpec, JsbsimAirframe, StartState
from sim_vehicles.dynamics.loiter_fit import air_course_rad, model_lag_after
from tssac_core.assurance.held_course import LineLaw, line_turn_rate
from tssac_core.assurance.lagged_backups import (
    AirframeLag,
    LagState,
    held_rollout,
    lag_gains,
    switched_lag_step,
    turn_keep_out,
)
from tssac_core.assurance.monitor import Limits

ENTRY_HOLD_S = 20.0
"""The steady maximum-rate turn before the reversal (s)."""
REVERSALS_S = (0.0, 0.5, 1.0, 2.0, 3.0, 5.0)
"""How long the reversal is commanded before the backup starts (0: from the steady turn itself)."""
TURN_S = 150.0
"""The backup's turn after its lead (s): past a whole circle at 300 m/s."""


@dataclass(frozen=True)
class HeldCase:
    """One run: the speed, the steady turn's direction before the reversal, the reversal's time, the lead and the
    backup's turn."""

    speed_m_s: float
    before_sign: float
    reversal_s: float
    lead_s: float
    turn_sign: float


def held_cases(speed_m_s: float, leads_s: Sequence[float]) -> list[HeldCase]:
    """The fit's runs at one speed: both ways before, every reversal, every held lead, both turns."""
    return [
        HeldCase(speed_m_s, b, r, lead, t)
        for b, r, lead, t in itertools.product((1.0, -1.0), REVERSALS_S, leads_s, (1.0, -1.0))
    ]


@dataclass(frozen=True)
class HeldRun:
    case: HeldCase
    airframe_residual_m: float
    """How far JSBSim's path lay from the prediction (module docstring)."""
    model_residual_m: float
    """How far the lag model's own flight under the law lay from it."""


def _predicted(
    x: float, y: float, v: float, heading: float, lag_state: LagState, case: HeldCase, lag: AirframeLag, dt_s: float,
    limit: float,
) -> tuple[np.ndarray, np.ndarray, float, tuple[float, float, float]]:  # fmt: skip
    """The monitor's prediction: the positions over the lead and the turn's samples (S,) each, the held course, and
    the turn's disk (centre x, y, radius)."""
    held_from, steps = round(lag.held_after_s / dt_s), round(case.lead_s / dt_s)
    lim = Limits(np.array([v]), np.array([v]), np.array([limit]), np.zeros(1))
    arrays = (np.array([x]), np.array([y]), np.array([v]), np.array([heading]))
    lead = held_rollout(*arrays, lag_state, steps, held_from, lag, lim, dt_s)
    end = (lead.xs[:, -1], lead.ys[:, -1], lead.speeds[:, -1], lead.headings[:, -1])
    path, cx, cy, radius = turn_keep_out(*end, lead.lag_after(steps), np.array([case.turn_sign]), lag, lim, dt_s)
    xs = np.concatenate([lead.xs[0], path.xs[0]])
    ys = np.concatenate([lead.ys[0], path.ys[0]])
    return xs, ys, float(lead.headings[0, held_from - 1]), (float(cx[0]), float(cy[0]), float(radius[0]))


Step = Callable[[float], tuple[float, float, float, float]]
"""Fly one world step at a heading-rate command; the position, ground velocity (east, north) after it."""


def _residual(
    step: Step, start: tuple[float, float], predicted: tuple[np.ndarray, np.ndarray, float, tuple[float, float, float]],
    case: HeldCase, held_from: int, dt_s: float, limit: float, law: LineLaw | None,
) -> float:  # fmt: skip
    """Fly the backup with ``step`` from ``start`` and measure it against ``predicted`` (module docstring); ``law``
    None: the lead flown open loop to its end (the negative control)."""
    xs, ys, course, (cx, cy, radius) = predicted
    lead = round(case.lead_s / dt_s)
    line: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    x, y = start
    gx, gy = 0.0, 0.0
    worst = 0.0
    for k in range(lead + round(TURN_S / dt_s)):
        if k == held_from and law is not None:
            line = (np.array([x]), np.array([y]), np.array([course]))
        if k >= lead:
            command = case.turn_sign * limit
        elif line is not None and law is not None:
            args = (np.array([x]), np.array([y]), np.array([gx]), np.array([gy]), line, np.array([limit]), law)
            command = float(line_turn_rate(*args)[0])
        else:
            command = 0.0
        x, y, gx, gy = step(command)
        if k < len(xs):
            worst = max(worst, math.hypot(x - xs[k], y - ys[k]))
        else:
            worst = max(worst, math.hypot(x - cx, y - cy) - radius)
    return worst


def fly_held(spec: AirframeSpec, case: HeldCase, lag: AirframeLag, dt_s: float, altitude_m: float,
             speed_limits_m_s: tuple[float, float], law: LineLaw | None = LineLaw(),
             turn_rate_max_rad_s: float = math.radians(5.0)) -> HeldRun:  # fmt: skip
    """One run (module docstring), on JSBSim and on the lag model ``lag`` (at the case's speed, with its
    ``held_after_s``); ``law`` None flies the lead open loop instead (the negative control)."""
    limit = turn_rate_max_rad_s
    entry = [case.before_sign * limit] * round(ENTRY_HOLD_S / dt_s) + [-case.before_sign * limit] * round(
        case.reversal_s / dt_s
    )
    held_from = round(lag.held_after_s / dt_s)
    low, high = speed_limits_m_s
    with JsbsimAirframe(spec, StartState(0.0, 0.0, altitude_m, case.speed_m_s, 0.3), speed_min_m_s=low,
                        speed_max_m_s=high) as airframe:  # fmt: skip
        state = airframe.state
        for command in entry:
            state = airframe.step(command, 0.0, dt_s)
        v, heading = state.airspeed_m_s, air_course_rad(state)
        lag_state = model_lag_after(entry, lag, dt_s)
        predicted = _predicted(state.east_m, state.north_m, v, heading, lag_state, case, lag, dt_s, limit)

        def jsbsim_step(command: float) -> tuple[float, float, float, float]:
            s = airframe.step(command, 0.0, dt_s)
            return (
                s.east_m,
                s.north_m,
                s.groundspeed_m_s * math.cos(s.course_rad),
                s.groundspeed_m_s * math.sin(s.course_rad),
            )

        flown = _residual(jsbsim_step, (state.east_m, state.north_m), predicted, case, held_from, dt_s, limit, law)
        start = (state.east_m, state.north_m, v, heading)
        model = _model_residual(start, lag_state, lag, predicted, case, dt_s, law, limit)
    return HeldRun(case, flown, model)


def _model_residual(
    start: tuple[float, float, float, float], lag_state: LagState, lag: AirframeLag,
    predicted: tuple[np.ndarray, np.ndarray, float, tuple[float, float, float]], case: HeldCase, dt_s: float,
    law: LineLaw | None, limit: float,
) -> float:  # fmt: skip
    """The same backup flown on the lag model itself, the law steering it."""
    x, y, v, phi = start
    omega = lag_state.omega_rad_s.copy()
    pending = list(lag_state.pending_rad_s[0])
    gains_in, gains_out = lag_gains(lag.tau_s, dt_s), lag_gains(lag.rollout_tau_s, dt_s)

    def model_step(command: float) -> tuple[float, float, float, float]:
        nonlocal x, y, phi, omega
        pending.append(command)
        mean, omega = switched_lag_step(omega, np.array([pending.pop(0)]), gains_in, gains_out)
        half = 0.5 * float(mean[0]) * dt_s
        chord = v * dt_s * math.sin(half) / half if half else v * dt_s
        x, y, phi = x + chord * math.cos(phi + half), y + chord * math.sin(phi + half), phi + float(mean[0]) * dt_s
        return x, y, v * math.cos(phi), v * math.sin(phi)

    held_from = round(lag.held_after_s / dt_s)
    return _residual(model_step, (x, y), predicted, case, held_from, dt_s, limit, law)


def held_residual_m(runs: Sequence[HeldRun]) -> float:
    """The fit's figure over ``runs`` (one speed): the largest residual of either flight, rounded up to the mm."""
    worst = max(max(r.airframe_residual_m, r.model_residual_m) for r in runs)
    return math.ceil(worst * 1000.0) / 1000.0
