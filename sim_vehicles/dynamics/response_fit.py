"""Fit an airframe's response to the world's setpoints from JSBSim step responses, and write it as data beside the
airframe's gains (the model and the file: :mod:`tssac_core.sim.airframe_response`).

    python -m sim_vehicles.dynamics.response_fit --aircraft f16            # writes airframes/f16.response.yaml
    python -m sim_vehicles.dynamics.response_fit --aircraft f16 --check    # fits again, compares with the file

At each speed of ``--speeds`` (calm air, level at ``--altitude-m``, world steps of ``--dt-s``):

* **Turn lag and residual.** Four runs under the airframe's inner loop, each held for two full circles: a
  maximum-rate turn left, then right, entered from straight flight; and a reversal from a steady maximum-rate turn
  one way to the other, both ways; and two roll-outs, from a steady maximum-rate turn either way into straight flight
  for ``ROLLOUT_S``. The model is flown from each run's state at the step. For each delay (whole world steps, up to
  ``MAX_DELAY_S``) the roll-out's time constant is the one (every ``TAU_GRID_S`` up to ``MAX_TAU_S``) whose paths
  keep closest to the roll-outs (least mean squared distance), and the roll-in's (also a reversal's) the one closest
  to the four turns; the delay is the one with the least mean square over all six runs,
  and the largest distance they leave is the residual, the error term a bound built on the model adds to its
  margin; the largest difference of heading over each run's first ``ROLLOUT_S``, the heading residual.
* **Acceleration.** Full and no throttle (commands of +-``ACCEL_COMMAND_M_S2``) from the speed, the airspeed's mean
  rate over ``--accel-window-s``; the inner loop's speed reference is not clipped during these runs.
* **The ground loiter** (the wind's backup): its turn-in (the delay and four of the longest time constant, up to a
  whole second), and how far beyond its radius the airframe and the lag model just fitted fly the loiter after a
  lead and the turn-in, from a reversal at full bank, straight flight and a turn its way, in calm air and in
  ``--wind-max-m-s`` from 16 directions, with how far the airframe's path and heading leave the model's on the way
  (:mod:`sim_vehicles.dynamics.loiter_fit`), at each speed and halfway to its neighbours (``--wind-max-m-s 0`` fits
  calm air only).
* **Held leads.** A backup whose lead is longer than the open roll-out the turns' fit covers holds its course after
  ``held_after_s`` (:func:`tssac_core.assurance.lagged_backups.held_rollout`): flown from states in and after a
  reversal, with each of ``held_leads_s`` and both turns after it, on JSBSim and on the lag model just fitted, the
  largest distance from the monitor's prediction is the held residual (:mod:`sim_vehicles.dynamics.held_fit`), at each
  speed and halfway to its neighbours (``--held-leads-s`` with no value: no held leads). ``--held-only`` flies only
  these runs and takes the rest from the file it rewrites (the same file a whole fit with these settings writes).

Everything is deterministic (JSBSim, steady winds, no turbulence): ``--check`` refits and compares with the file at
1e-9.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, fields
from pathlib import Path

import jsbsim
import numpy as np

from sim_vehicles.dynamics.held_fit import fly_held, held_cases, held_residual_m
from sim_vehicles.dynamics.jsbsim_airframe import (
    AirframeError,
    AirframeSpec,
    JsbsimAirframe,
    StartState,
    airframe_path,
    load_airframe,
)
from sim_vehicles.dynamics.loiter_fit import (
    FitFlight,
    LoiterFigures,
    LoiterRun,
    fly_loiter,
    loiter_cases,
    loiter_figures,
)
from tssac_core.assurance.ground_loiter import LoiterLaw, settled_turn_in_s
from tssac_core.assurance.lagged_backups import lag_gains, switched_lag_step
from tssac_core.common.cli import UsageError, run
from tssac_core.common.files import sha256_file
from tssac_core.sim.airframe_response import (
    RESPONSE_SCHEMA,
    AirframeResponse,
    ResponseFileError,
    airframe_lag,
    dump_response,
    load_response,
)

MAX_DELAY_S = 2.0
MAX_TAU_S = 6.0
TAU_GRID_S = 0.01
REVERSAL_LEAD_S = 30.0
"""A reversal starts from this long in a steady maximum-rate turn the other way."""
ROLLOUT_S = 40.0
"""A roll-out run's length: longer than the monitor's longest straight lead (32 s)."""
ACCEL_COMMAND_M_S2 = 10.0
"""The acceleration commanded to measure what the airframe achieves (more than it can: the throttle saturates)."""
SPEED_REFERENCE_SPAN_M_S = (50.0, 500.0)
"""The inner loop's speed limits during the acceleration runs (wide: the airframe, not the clip, sets the rate)."""


@dataclass(frozen=True)
class Turn:
    """A recorded turn: the commands held per world step, and what the airframe did after each."""

    omega_before_rad_s: float
    """The steady turn rate when the step came (0 from straight flight)."""
    command_rad_s: float
    """The heading-rate command held from step 0 on."""
    rates_rad_s: np.ndarray
    """(K,) the course rate over each step."""
    xy_m: np.ndarray
    """(K + 1, 2) positions, from the step's start."""
    course_rad: float
    """Course at the step's start (counter-clockwise from east)."""
    speed_m_s: float
    """Groundspeed at the step's start."""


def fly_turn(
    spec: AirframeSpec,
    speed_m_s: float,
    altitude_m: float,
    dt_s: float,
    before_rad_s: float,
    command_rad_s: float,
    duration_s: float,
) -> Turn:
    """Fly ``REVERSAL_LEAD_S`` at ``before_rad_s`` if it is not 0, then ``command_rad_s`` for ``duration_s``."""
    start = StartState(0.0, 0.0, altitude_m, speed_m_s, 0.0)
    with JsbsimAirframe(spec, start, speed_min_m_s=min(speed_m_s, 150.0), speed_max_m_s=max(speed_m_s, 300.0)) as a:
        if before_rad_s != 0.0:
            for _ in range(round(REVERSAL_LEAD_S / dt_s)):
                a.step(before_rad_s, 0.0, dt_s)
        s0 = a.state
        xy = [(s0.east_m, s0.north_m)]
        rates = []
        for _ in range(round(duration_s / dt_s)):
            s = a.step(command_rad_s, 0.0, dt_s)
            xy.append((s.east_m, s.north_m))
            rates.append(s.turn_rate_rad_s)
    origin = np.array(xy[0])
    return Turn(before_rad_s, command_rad_s, np.array(rates), np.array(xy) - origin, s0.course_rad, s0.groundspeed_m_s)


def lag_rates(before: float, command: float, steps: int, delay_steps: int, taus: np.ndarray, dt_s: float) -> np.ndarray:
    """The model's mean turn rate over each of ``steps`` steps of a command held from step 0, (G, steps) for G time
    constants at once (:func:`tssac_core.assurance.lagged_backups.lag_step_mean`'s model): ``before`` for the delay,
    then the first-order lag toward the command, omega(t) = command + (before - command) exp(-t / tau), whose mean
    over step j of it is command + (before - command) (1 - g)^j h, with g = 1 - exp(-dt / tau), h = tau g / dt."""
    g, h = lag_gains(taus, dt_s)
    j = np.arange(steps) - delay_steps
    factor = np.where(j[None, :] >= 0, (1.0 - g[:, None]) ** np.maximum(j, 0)[None, :] * h[:, None], 1.0)
    return command + (before - command) * factor


def switched_lag_rates(
    before: float, command: float, steps: int, delay_steps: int, taus: np.ndarray, rollout_tau_s: float, dt_s: float
) -> np.ndarray:
    """The model's mean turn rate over each of ``steps`` steps, as :func:`lag_rates`, with the roll-out's time
    constant while it rolls out (:func:`tssac_core.assurance.lagged_backups.switched_lag_step`), (G,
    steps) for G roll-in time constants at once: a recursion."""
    gains_in = lag_gains(taus, dt_s)
    gains_out = lag_gains(np.full(len(taus), rollout_tau_s), dt_s)
    omega = np.full(len(taus), before, dtype=np.float64)
    out = np.empty((len(taus), steps))
    out[:, : min(delay_steps, steps)] = before
    for k in range(delay_steps, steps):
        out[:, k], omega = switched_lag_step(omega, np.full(len(taus), command), gains_in, gains_out)
    return out


@dataclass(frozen=True)
class LagFit:
    """The fitted lag at one speed."""

    delay_steps: int
    tau_s: float
    """Rolling in."""
    rollout_tau_s: float
    residual_m: float
    """The largest distance between the airframe's and the model's paths over every run."""
    heading_residual_rad: float = 0.0
    """The largest difference between the airframe's course and the model's heading over every run's first
    ``ROLLOUT_S``."""


def fit_lag(turns: Sequence[Turn], rollouts: Sequence[Turn], dt_s: float) -> LagFit:
    """The delay and the two time constants whose model paths keep closest to the airframe's in the least-squares
    sense (the module docstring's order; the largest distance has several nearly equal minima far apart in delay and
    time constant, the mean squared one does not), and the largest distance they leave. An exhaustive grid."""
    taus = np.arange(TAU_GRID_S, MAX_TAU_S + TAU_GRID_S / 2, TAU_GRID_S)
    best: tuple[float, LagFit] | None = None
    for delay in range(round(MAX_DELAY_S / dt_s) + 1):
        out_squares, _, rollout_tau, out_worst = _fit_at_delay(rollouts, delay, taus, dt_s, None)
        in_squares, _, tau, in_worst = _fit_at_delay(turns, delay, taus, dt_s, rollout_tau)
        fit = LagFit(delay, tau, rollout_tau, max(out_worst, in_worst))
        if best is None or out_squares + in_squares < best[0]:
            best = (out_squares + in_squares, fit)
    assert best is not None
    fit = best[1]
    turned = [heading_error_rad(t, fit, dt_s) for t in [*turns, *rollouts]]
    return dataclasses.replace(fit, heading_residual_rad=max(turned))


def heading_error_rad(turn: Turn, fit: LagFit, dt_s: float) -> float:
    """The largest difference over a run's first ``ROLLOUT_S`` (the longest straight lead and more) between the
    airframe's course and the fitted model's heading, both turned from the run's start by their own rates: how far
    off the model's heading may be where a backup's loiter starts."""
    steps = min(len(turn.rates_rad_s), round(ROLLOUT_S / dt_s))
    before, command, tau = turn.omega_before_rad_s, turn.command_rad_s, np.array([fit.tau_s])
    model = switched_lag_rates(before, command, steps, fit.delay_steps, tau, fit.rollout_tau_s, dt_s)[0]
    return float(np.abs(np.cumsum((turn.rates_rad_s[:steps] - model) * dt_s)).max())


def _fit_at_delay(
    turns: Sequence[Turn], delay: int, taus: np.ndarray, dt_s: float, rollout_tau_s: float | None
) -> tuple[float, int, float, float]:
    """(sum over the turns of the mean squared distance, delay, tau, largest distance) for the tau of ``taus`` with
    the least sum; ``rollout_tau_s`` None: one time constant both ways."""
    squares = np.zeros(len(taus))
    worst = np.zeros(len(taus))
    for t in turns:
        error = t.xy_m[None] - model_paths(t, delay, taus, dt_s, rollout_tau_s)
        distance = np.hypot(error[..., 0], error[..., 1])
        squares += (distance**2).mean(axis=1)
        worst = np.maximum(worst, distance.max(axis=1))
    i = int(np.argmin(squares))
    return float(squares[i]), delay, round(float(taus[i]), 9), float(worst[i])


def model_paths(
    turn: Turn, delay_steps: int, taus: np.ndarray, dt_s: float, rollout_tau_s: float | None = None
) -> np.ndarray:
    """(G, K + 1, 2) the model's positions over the turn for G time constants: eq. 5's exact arcs at the start's
    speed and the lagged rate's mean over each step (``rollout_tau_s`` None: one time constant both ways)."""
    steps = len(turn.rates_rad_s)
    if rollout_tau_s is None:
        rates = lag_rates(turn.omega_before_rad_s, turn.command_rad_s, steps, delay_steps, taus, dt_s)
    else:
        before, command = turn.omega_before_rad_s, turn.command_rad_s
        rates = switched_lag_rates(before, command, steps, delay_steps, taus, rollout_tau_s, dt_s)
    heading = turn.course_rad + np.concatenate([np.zeros((len(taus), 1)), np.cumsum(rates * dt_s, axis=1)], axis=1)
    half = rates * dt_s / 2.0
    chord = turn.speed_m_s * dt_s * np.sinc(half / np.pi)  # np.sinc(x) = sin(pi x) / (pi x)
    mid = heading[:, :-1] + half
    steps_xy = np.stack([chord * np.cos(mid), chord * np.sin(mid)], axis=2)
    return np.concatenate([np.zeros((len(taus), 1, 2)), np.cumsum(steps_xy, axis=1)], axis=1)


def mean_accel(
    spec: AirframeSpec, speed_m_s: float, altitude_m: float, dt_s: float, accel_cmd: float, window_s: float
) -> float:
    """The airspeed's mean rate over ``window_s`` of ``accel_cmd`` (m/s^2) from ``speed_m_s``."""
    start = StartState(0.0, 0.0, altitude_m, speed_m_s, 0.0)
    low, high = SPEED_REFERENCE_SPAN_M_S
    with JsbsimAirframe(spec, start, speed_min_m_s=low, speed_max_m_s=high) as a:
        v0 = a.state.airspeed_m_s
        for _ in range(round(window_s / dt_s)):
            a.step(0.0, accel_cmd, dt_s)
        return (a.state.airspeed_m_s - v0) / window_s


@dataclass(frozen=True)
class FitSettings:
    """What the fit flies."""

    speeds_m_s: tuple[float, ...] = (150.0, 200.0, 250.0, 300.0)
    turn_rate_max_deg_s: float = 5.0
    altitude_m: float = 5000.0
    dt_s: float = 0.1
    accel_window_s: float = 15.0
    wind_max_m_s: float = 10.0
    """The steady wind the loiter's excursion is measured in (0: calm air only)."""
    loiter_law: LoiterLaw = LoiterLaw()
    held_leads_s: tuple[float, ...] = (64.0, 128.0)
    """The leads that hold their course after ``held_after_s`` (s; empty: none fitted, none offered)."""
    held_after_s: float = 32.0
    """The open part of a held lead (s): the monitor's longest open lead, which the turns' fit covers."""


def fit_response(aircraft: str, settings: FitSettings, command: str) -> AirframeResponse:
    """Fly the runs of the module docstring for ``aircraft`` (a bundled name or a file) and fit its response."""
    path = airframe_path(aircraft)
    spec = load_airframe(path)
    w = math.radians(settings.turn_rate_max_deg_s)
    circles_s = 2.0 * 2.0 * math.pi / w
    keys = ("delay", "tau", "rollout", "residual", "heading", "accel", "decel")
    table: dict[str, list[float]] = {k: [] for k in keys}
    for v in settings.speeds_m_s:
        turns = [
            fly_turn(spec, v, settings.altitude_m, settings.dt_s, before, after, circles_s)
            for before, after in ((0.0, w), (0.0, -w), (-w, w), (w, -w))
        ]
        rollouts = [fly_turn(spec, v, settings.altitude_m, settings.dt_s, before, 0.0, ROLLOUT_S) for before in (w, -w)]
        fit = fit_lag(turns, rollouts, settings.dt_s)
        table["delay"].append(round(fit.delay_steps * settings.dt_s, 9))
        table["tau"].append(round(fit.tau_s, 9))
        table["rollout"].append(round(fit.rollout_tau_s, 9))
        table["residual"].append(round(fit.residual_m, 3))
        table["heading"].append(round(math.degrees(fit.heading_residual_rad), 3))
        for key, sign in (("accel", 1.0), ("decel", -1.0)):
            command_m_s2 = sign * ACCEL_COMMAND_M_S2
            a = mean_accel(spec, v, settings.altitude_m, settings.dt_s, command_m_s2, settings.accel_window_s)
            table[key].append(round(a, 4))
    law = settings.loiter_law
    provisional = AirframeResponse(
        schema=RESPONSE_SCHEMA,
        aircraft=path.stem,
        airframe_sha256=sha256_file(path),
        jsbsim_version=jsbsim.__version__,
        command=command,
        altitude_m=settings.altitude_m,
        dt_s=settings.dt_s,
        turn_rate_max_rad_s=w,
        speeds_m_s=tuple(settings.speeds_m_s),
        turn_delay_s=tuple(table["delay"]),
        turn_tau_s=tuple(table["tau"]),
        turn_residual_m=tuple(table["residual"]),
        accel_max_m_s2=tuple(table["accel"]),
        decel_max_m_s2=tuple(table["decel"]),
        accel_window_s=settings.accel_window_s,
        turn_rollout_tau_s=tuple(table["rollout"]),
        turn_heading_residual_deg=tuple(table["heading"]),
        loiter_authority=law.authority,
        loiter_lookahead_share=law.lookahead_share,
        loiter_track_gain_1_s=law.track_gain_1_s,
    )
    turn_in = settled_turn_in_s(max(table["delay"]), max(table["tau"] + table["rollout"]))
    figures = fit_loiter(spec, provisional, settings, turn_in)
    return dataclasses.replace(
        provisional,
        loiter_wind_max_m_s=settings.wind_max_m_s,
        loiter_turn_in_s=turn_in,
        loiter_excursion_m=tuple(f.excursion_m for f in figures),
        loiter_residual_m=tuple(f.path_residual_m for f in figures),
        loiter_heading_residual_deg=tuple(round(math.degrees(f.heading_residual_rad), 4) for f in figures),
        held_after_s=settings.held_after_s,
        held_leads_s=settings.held_leads_s,
        held_residual_m=fit_held(spec, provisional, settings),
    )


def refit_held(aircraft: str, stored: AirframeResponse, settings: FitSettings, command: str) -> AirframeResponse:
    """``stored`` with its held leads fitted again under ``settings`` (what :func:`fit_response` would write, the
    turns' and the loiter's runs not flown again: the file must come from a fit of the same speeds, turn rate,
    altitude, step, acceleration window and loiter wind)."""
    fitted_as = (
        stored.speeds_m_s, stored.turn_rate_max_rad_s, stored.altitude_m, stored.dt_s, stored.accel_window_s,
        stored.loiter_wind_max_m_s,
    )  # fmt: skip
    asked = (
        settings.speeds_m_s, math.radians(settings.turn_rate_max_deg_s), settings.altitude_m, settings.dt_s,
        settings.accel_window_s, settings.wind_max_m_s,
    )  # fmt: skip
    if fitted_as != asked:
        raise ResponseFileError(
            f"--held-only: the file was fitted at speeds {list(stored.speeds_m_s)} m/s, turn rate "
            f"{math.degrees(stored.turn_rate_max_rad_s):g} deg/s, altitude {stored.altitude_m:g} m, step "
            f"{stored.dt_s:g} s, acceleration window {stored.accel_window_s:g} s, loiter wind "
            f"{stored.loiter_wind_max_m_s:g} m/s; this command asks for other ones: fit it whole"
        )
    spec = load_airframe(airframe_path(aircraft))
    return dataclasses.replace(
        stored,
        command=command,
        held_after_s=settings.held_after_s,
        held_leads_s=settings.held_leads_s,
        held_residual_m=fit_held(spec, stored, settings),
    )


def _neighbour_bands(speeds: Sequence[float]) -> tuple[list[float], list[list[float]]]:
    """Every speed a fit flies (the tabled ones and halfway between neighbours, ascending) and, per tabled speed, the
    ones its figure covers: itself and halfway to each neighbour (so that the worse neighbour's figure covers every
    speed between two)."""
    halfway = [(a + b) / 2.0 for a, b in zip(speeds, speeds[1:])]
    bands = [[v] + halfway[max(k - 1, 0) : k + 1] for k, v in enumerate(speeds)]
    return sorted(set(speeds) | set(halfway)), bands


def fit_held(spec: AirframeSpec, lag: AirframeResponse, settings: FitSettings) -> tuple[float, ...]:
    """The held residual per tabled speed (module docstring; empty without held leads): the largest of the runs at
    the speed and halfway to each neighbour, each flown with the lag just fitted (interpolated as the monitor reads
    it)."""
    if not settings.held_leads_s:
        return ()
    flown, bands = _neighbour_bands(settings.speeds_m_s)
    limits = (settings.speeds_m_s[0], settings.speeds_m_s[-1])
    runs = {}
    for v in flown:
        air = dataclasses.replace(airframe_lag(lag, np.array([v]), settings.dt_s), held_after_s=settings.held_after_s)
        cases = held_cases(v, settings.held_leads_s)
        w = lag.turn_rate_max_rad_s
        runs[v] = [
            fly_held(spec, c, air, settings.dt_s, settings.altitude_m, limits, turn_rate_max_rad_s=w) for c in cases
        ]
    return tuple(held_residual_m([run for b in band for run in runs[b]]) for band in bands)


def fit_loiter(
    spec: AirframeSpec, lag: AirframeResponse, settings: FitSettings, turn_in_s: float
) -> tuple[LoiterFigures, ...]:
    """The loiter's figures per tabled speed (module docstring): the largest of the runs at the speed and halfway to
    each tabled neighbour (so that the worse neighbour's figure covers every speed between two), each run flown with
    the lag just fitted (interpolated between tabled speeds, as the monitor reads it)."""
    speeds = settings.speeds_m_s
    flown, bands = _neighbour_bands(speeds)
    flight = FitFlight(
        spec, settings.wind_max_m_s, settings.loiter_law, lag.turn_rate_max_rad_s, settings.altitude_m,
        settings.dt_s, (speeds[0], speeds[-1]), turn_in_s,
    )  # fmt: skip
    runs: dict[float, list[LoiterRun]] = {}
    for v in flown:
        air = airframe_lag(lag, np.array([v]), settings.dt_s)
        runs[v] = [fly_loiter(flight, case, air) for case in loiter_cases(v, settings.wind_max_m_s)]
    return tuple(loiter_figures([run for b in band for run in runs[b]]) for band in bands)


def differences(fitted: AirframeResponse, stored: AirframeResponse, tolerance: float = 1e-9) -> list[str]:
    """The fields where a fresh fit and a stored file differ (numbers beyond ``tolerance``; ``command`` ignored)."""
    out = []
    for f in fields(AirframeResponse):
        a, b = getattr(fitted, f.name), getattr(stored, f.name)
        if f.name == "command":
            continue
        if isinstance(a, tuple) and isinstance(b, tuple) and len(a) == len(b):
            same = all(abs(x - y) <= tolerance * max(1.0, abs(y)) for x, y in zip(a, b))
        elif isinstance(a, float) and isinstance(b, float):
            same = abs(a - b) <= tolerance * max(1.0, abs(b))
        else:
            same = a == b
        if not same:
            out.append(f"{f.name}: fitted {a}, stored {b}")
    return out


def response_path(aircraft: str) -> Path:
    """Where an airframe's response file lives: beside its airframe file."""
    path = airframe_path(aircraft)
    return path.with_name(f"{path.stem}.response.yaml")


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="python -m sim_vehicles.dynamics.response_fit",
        description="Fit an airframe's turn lag and achievable acceleration from JSBSim step responses and write them "
        "beside its airframe file (or, with --check, compare a fresh fit with that file).",
    )
    p.add_argument("--aircraft", default="f16", help="a bundled airframe (f16) or an airframe YAML file")
    p.add_argument("--out", type=Path, help="where to write (default: <airframe>.response.yaml beside the airframe)")
    p.add_argument("--check", action="store_true", help="fit and compare with the file instead of writing it")
    p.add_argument("--speeds", type=float, nargs="+", default=list(FitSettings.speeds_m_s), help="speeds (m/s)")
    p.add_argument("--turn-rate-deg-s", type=float, default=FitSettings.turn_rate_max_deg_s)
    p.add_argument("--altitude-m", type=float, default=FitSettings.altitude_m)
    p.add_argument("--accel-window-s", type=float, default=FitSettings.accel_window_s)
    p.add_argument(
        "--wind-max-m-s",
        type=float,
        default=FitSettings.wind_max_m_s,
        help="the steady wind the ground loiter is measured in, from 16 directions (m/s; 0: calm air only)",
    )
    p.add_argument(
        "--held-leads-s",
        type=float,
        nargs="*",
        default=list(FitSettings.held_leads_s),
        help="the leads that hold their course after --held-after-s (s; none given: no held leads)",
    )
    p.add_argument("--held-after-s", type=float, default=FitSettings.held_after_s, help="a held lead's open part (s)")
    p.add_argument(
        "--held-only",
        action="store_true",
        help="fly only the held leads' runs; the turns, accelerations and loiter come from the file this rewrites",
    )
    args = p.parse_args(argv)
    speeds = args.speeds
    if any(not (math.isfinite(v) and 0 < v < 1000) for v in speeds) or sorted(set(speeds)) != speeds:
        raise UsageError("--speeds: give distinct speeds in ascending order, each in (0, 1000) m/s")
    if not 0 < args.turn_rate_deg_s <= 30 or not 0 < args.altitude_m <= 20000 or not 1 <= args.accel_window_s <= 120:
        raise UsageError(
            "--turn-rate-deg-s must be in (0, 30], --altitude-m in (0, 20000], --accel-window-s in [1, 120]"
        )
    if not 0 <= args.wind_max_m_s < 0.5 * speeds[0]:
        raise UsageError(f"--wind-max-m-s must be in [0, {0.5 * speeds[0]:g}) (half the slowest speed)")
    held, after = args.held_leads_s, args.held_after_s
    if not (math.isfinite(after) and 1.0 <= after <= 120.0):
        raise UsageError("--held-after-s must be in [1, 120] s")
    if any(not (math.isfinite(t) and after < t <= 600.0) for t in held) or sorted(set(held)) != held:
        raise UsageError(f"--held-leads-s: give distinct leads in ascending order, each in ({after:g}, 600] s")
    if args.held_only and args.check:
        raise UsageError("--held-only rewrites the held leads of a file; --check compares a whole fit with one")
    return args


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    settings = FitSettings(
        tuple(args.speeds),
        args.turn_rate_deg_s,
        args.altitude_m,
        0.1,
        args.accel_window_s,
        args.wind_max_m_s,
        held_leads_s=tuple(args.held_leads_s),
        held_after_s=args.held_after_s,
    )
    try:
        out = args.out or response_path(args.aircraft)
        words = ["python -m sim_vehicles.dynamics.response_fit", "--aircraft", str(args.aircraft)]
        if settings != FitSettings():
            words += ["--speeds", *(f"{v:g}" for v in args.speeds), "--turn-rate-deg-s", f"{args.turn_rate_deg_s:g}"]
            words += ["--altitude-m", f"{args.altitude_m:g}", "--accel-window-s", f"{args.accel_window_s:g}"]
            words += [
                "--wind-max-m-s",
                f"{args.wind_max_m_s:g}",
                "--held-leads-s",
                *(f"{t:g}" for t in args.held_leads_s),
                "--held-after-s",
                f"{args.held_after_s:g}",
            ]
        stored = load_response(out, airframe_path(args.aircraft)) if args.check or args.held_only else None
        if args.held_only:
            assert stored is not None
            fitted = refit_held(args.aircraft, stored, settings, " ".join(words))
            stored = None
        else:
            fitted = fit_response(args.aircraft, settings, " ".join(words))
        if stored is not None:
            diff = differences(fitted, stored)
            if diff:
                print(f"{out}: differs from a fresh fit: " + "; ".join(diff), file=sys.stderr)
                return 1
            print(f"{out}: equal to a fresh fit")
            return 0
    except (AirframeError, ResponseFileError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out.write_text(dump_response(fitted))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
