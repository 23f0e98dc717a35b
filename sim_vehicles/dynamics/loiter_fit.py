"""Measure how far beyond its radius an airframe flies the ground loiter (:mod:`tssac_core.assurance.ground_loiter`),
and how far its path and heading leave the lag model's over a backup's lead and turn-in: in JSBSim under the
airframe's inner loop, from the worst states a backup can start from, in calm air and in the declared maximum wind
from every direction.

A run (:func:`fly_loiter`): the airframe flies ``ENTRY_HOLD_S`` at the entry's heading rate (a maximum-rate turn
against the loiter's direction, straight flight, or a maximum-rate turn its way), so its bank has settled; there the
backup starts, as the monitor predicts it: straight for the lead, then the turn-in (a maximum-rate turn the loiter's
way for ``turn_in_s``), then the loiter, its circle sized for the maximum wind at the airspeed and its centre at R from
the vehicle on the turn's side of its ground track (:func:`~tssac_core.assurance.ground_loiter.loiter_centre`); the law
steers from the airframe's true position, ground velocity and wind every world step for ``laps`` laps. The lag model
flies the same backup from the same state, carried by the same wind, and its own loiter from where its turn-in ends.
A run measures the larger of the two flights' largest distance beyond the radius (the excursion), the largest
distance between the two paths over the lead and turn-in (the path residual) and the difference of their headings
where the loiter starts (the heading residual); the fit's figures, per speed, are the largest of its runs
(:func:`loiter_figures`).

``python -m sim_vehicles.dynamics.response_fit`` runs this after the lag's fit and writes the figures into the
response file (``loiter_*``).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sim_vehicles.dynamics.jsbsim_airframe import AirframeSpec, AirframeState, JsbsimAirframe, StartState, Wind
from tssac_core.assurance.ground_loiter import (
    LoiterLaw,
    carried_rollout,
    fly_loiter_on_model,
    loiter_centre,
    loiter_radius_m,
    loiter_turn_rate,
    turn_in_steps,
)
from tssac_core.assurance.lagged_backups import AirframeLag, LagState, lag_gains, switched_lag_step
from tssac_core.assurance.monitor import Limits

ENTRY_HOLD_S = 10.0
"""How long the entry's heading rate is held before the backup starts: the f16's bank settles within 3 s."""
ENTRIES = ((-1.0, 0.0), (-1.0, 4.0), (-1.0, 32.0), (0.0, 0.0), (1.0, 0.0), (1.0, 4.0), (1.0, 32.0))
"""The backups the fit flies, as (the heading rate it starts from, in turn-rate limits toward the loiter's turn; its
straight lead, s): a reversal at full bank straight into the turn-in, and rolled out over the shortest and the
longest of the monitor's leads first (:attr:`~tssac_core.assurance.monitor.ShieldConfig.straight_leads_s`: after a
roll-out the model's heading is off by a constant, so the path's error grows along the lead); from straight flight;
from a maximum-rate turn its way, at once and after those leads. ``tests/test_ground_loiter.py`` flies mid-roll
states, the leads between and other headings against the fitted figures."""
DIRECTIONS = 16
"""Wind directions per speed, evenly spaced from north."""
LAPS = 1.0
"""A run's length in laps of its circle at the groundspeed into the wind: the entry's excursion comes within the
first quarter; on the model the loop settles within a lap and does not grow after it (``tests/test_ground_loiter.py``
flies four)."""
START_HEADING_RAD = 0.3
"""The runs' start heading (counter-clockwise from east): away from the axes, so no wind blows along one."""


@dataclass(frozen=True)
class LoiterCase:
    """One run: the speed, the steady wind, the entry's heading rate (in turn-rate limits toward the loiter's turn)
    and the loiter's direction (+1 counter-clockwise); optionally the backup's straight lead, the start heading and a
    roll caught part-way (the entry's opposite rate commanded for ``reverse_steps`` world steps after the hold:
    mid-roll)."""

    speed_m_s: float
    wind: Wind
    entry: float
    sign: float
    lead_s: float = 0.0
    heading_rad: float = START_HEADING_RAD
    reverse_steps: int = 0

    def entry_commands(self, turn_rate_max_rad_s: float, dt_s: float) -> list[float]:
        """The heading-rate commands flown before the backup starts (rad/s)."""
        rate = self.entry * self.sign * turn_rate_max_rad_s
        return [rate] * round(ENTRY_HOLD_S / dt_s) + [-rate] * self.reverse_steps

    def backup_commands(self, turn_rate_max_rad_s: float, dt_s: float, turn_in_s: float) -> np.ndarray:
        """The backup's heading-rate commands before its loiter (rad/s): the lead, then the turn-in."""
        turn = [self.sign * turn_rate_max_rad_s] * turn_in_steps(turn_in_s, dt_s)
        return np.array([0.0] * round(self.lead_s / dt_s) + turn)


@dataclass(frozen=True)
class LoiterRun:
    """What a run measured (m, rad)."""

    case: LoiterCase
    radius_m: float
    airframe_excursion_m: float
    """The airframe's largest distance beyond the radius from the centre."""
    model_excursion_m: float
    """The lag model's, from its own turn-in's end."""
    path_residual_m: float = 0.0
    """The largest distance between the airframe's and the model's paths over the lead and turn-in."""
    heading_residual_rad: float = 0.0
    """The difference of their headings where the loiter starts."""

    @property
    def excursion_m(self) -> float:
        return max(self.airframe_excursion_m, self.model_excursion_m)


def loiter_cases(speed_m_s: float, wind_max_m_s: float, directions: int = DIRECTIONS) -> list[LoiterCase]:
    """The fit's runs at one speed: calm air and ``wind_max`` from ``directions`` directions, each entry, both ways."""
    winds = [Wind()] + [Wind(speed_m_s=wind_max_m_s, from_deg=360.0 * k / directions) for k in range(directions)]
    if wind_max_m_s == 0.0:
        winds = winds[:1]
    return [LoiterCase(speed_m_s, w, e, s, lead) for w, (e, lead), s in itertools.product(winds, ENTRIES, (1.0, -1.0))]


def model_lag_after(commands: Sequence[float], lag: AirframeLag, dt_s: float) -> LagState:
    """The lag model's state (M = 1) after ``commands``, from a steady state at the first of them: the rate it flies and
    the commands its delay still holds back."""
    width = int(lag.delay_steps[0])
    history = [commands[0]] * (width + 1) + list(commands)
    omega = np.array([commands[0]])
    gains_in, gains_out = lag_gains(lag.tau_s, dt_s), lag_gains(lag.rollout_tau_s, dt_s)
    for k in range(len(commands)):
        _, omega = switched_lag_step(omega, np.array([history[k + 1]]), gains_in, gains_out)
    return LagState(omega, np.array([history[len(history) - width :]]))


def air_course_rad(state: AirframeState) -> float:
    """The direction of the airframe's velocity through the air (counter-clockwise from east): the heading of the
    monitor's model, which a companion takes from its ground velocity less the wind (in a banked turn the nose, the
    yaw, points off it by about the angle of attack times the bank's sine: degrees)."""
    gx, gy = _ground(state)
    return math.atan2(float(gy[0]) - state.wind_north_m_s, float(gx[0]) - state.wind_east_m_s)


def _ground(state: AirframeState) -> tuple[np.ndarray, np.ndarray]:
    speed, course = state.groundspeed_m_s, state.course_rad
    return np.array([speed * math.cos(course)]), np.array([speed * math.sin(course)])


@dataclass(frozen=True)
class FitFlight:
    """What every run of a fit shares."""

    spec: AirframeSpec
    wind_max_m_s: float
    law: LoiterLaw
    turn_rate_max_rad_s: float
    altitude_m: float
    dt_s: float
    speed_limits_m_s: tuple[float, float]
    turn_in_s: float
    laps: float = LAPS


def _predicted(
    state: AirframeState,
    case: LoiterCase,
    lag: AirframeLag,
    flight: FitFlight,
    commands: np.ndarray,
    entry: list[float],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, LagState]:
    """The lag model's backup from the airframe's ``state``: its positions over the ground after each of ``commands``
    (S,) each, its heading and speed at the end, and the lag's state there (M = 1)."""
    x, y = np.array([state.east_m]), np.array([state.north_m])
    v, heading = np.array([state.airspeed_m_s]), np.array([air_course_rad(state)])
    lag_state = model_lag_after(entry, lag, flight.dt_s)
    steps = len(commands)
    if steps == 0:
        return x, y, heading, v, lag_state
    held = Limits(v, v, np.array([flight.turn_rate_max_rad_s]), np.zeros(1))
    drift = (case.wind.east_m_s, case.wind.north_m_s)
    path = carried_rollout(x, y, v, heading, lag_state, commands[None, :], lag, held, flight.dt_s, drift)
    return path.xs[0], path.ys[0], path.headings[:, -1], v, path.lag_after(steps)


def fly_loiter(flight: FitFlight, case: LoiterCase, lag: AirframeLag) -> LoiterRun:
    """One run (module docstring): the airframe in JSBSim and ``lag`` (the airframe's model at the case's speed)."""
    dt_s, entry = flight.dt_s, case.entry_commands(flight.turn_rate_max_rad_s, flight.dt_s)
    commands = case.backup_commands(flight.turn_rate_max_rad_s, dt_s, flight.turn_in_s)
    start = StartState(0.0, 0.0, flight.altitude_m, case.speed_m_s, case.heading_rad)
    low, high = flight.speed_limits_m_s
    limit = np.array([flight.turn_rate_max_rad_s])
    wind_max, law = flight.wind_max_m_s, flight.law
    with JsbsimAirframe(flight.spec, start, wind=case.wind, speed_min_m_s=low, speed_max_m_s=high) as airframe:
        state = airframe.state
        for command in entry:
            state = airframe.step(command, 0.0, dt_s)
        xs, ys, m_heading, m_speed, m_lag = _predicted(state, case, lag, flight, commands, entry)
        path_residual = 0.0
        for k, command in enumerate(commands):
            state = airframe.step(float(command), 0.0, dt_s)
            path_residual = max(path_residual, math.hypot(state.east_m - xs[k], state.north_m - ys[k]))
        heading = air_course_rad(state)
        heading_residual = abs((heading - m_heading[0] + math.pi) % (2.0 * math.pi) - math.pi)
        x, y = np.array([state.east_m]), np.array([state.north_m])
        airspeed = np.array([state.airspeed_m_s])
        radius = loiter_radius_m(airspeed, wind_max, limit, law.authority)
        gx, gy = _ground(state)
        cx, cy = loiter_centre(x, y, gx, gy, case.sign, radius)
        steps = math.ceil(flight.laps * 2.0 * math.pi * radius[0] / (airspeed[0] - wind_max) / dt_s)
        far = -math.inf
        for _ in range(steps):
            gx, gy = _ground(state)
            here = np.array([state.east_m]), np.array([state.north_m])
            wind = state.wind_east_m_s, state.wind_north_m_s
            rate = loiter_turn_rate(*here, gx, gy, *wind, cx, cy, radius, case.sign, limit, law)
            state = airframe.step(float(rate[0]), 0.0, dt_s)
            far = max(far, math.hypot(state.east_m - cx[0], state.north_m - cy[0]) - radius[0])
    m_radius = loiter_radius_m(m_speed, wind_max, limit, law.authority)
    m_wind = (case.wind.east_m_s, case.wind.north_m_s)
    mgx, mgy = m_speed * np.cos(m_heading) + m_wind[0], m_speed * np.sin(m_heading) + m_wind[1]
    mx, my = np.array([xs[-1]]), np.array([ys[-1]])
    mcx, mcy = loiter_centre(mx, my, mgx, mgy, case.sign, m_radius)
    model = fly_loiter_on_model(
        mx, my, m_speed, m_heading, m_lag, m_wind, (mcx, mcy), m_radius, case.sign, lag, limit, law, dt_s, steps
    )
    model_far = float((np.hypot(model.xs[0] - mcx[0], model.ys[0] - mcy[0]) - m_radius[0]).max())
    return LoiterRun(case, float(radius[0]), far, model_far, path_residual, heading_residual)


@dataclass(frozen=True)
class LoiterFigures:
    """The fit's figures at one speed: the largest of its runs', rounded up (to the millimetre, the microradian)."""

    excursion_m: float
    path_residual_m: float
    heading_residual_rad: float


def loiter_figures(runs: Sequence[LoiterRun]) -> LoiterFigures:
    """The largest of the runs' figures, rounded up."""
    return LoiterFigures(
        math.ceil(max(run.excursion_m for run in runs) * 1000.0) / 1000.0,
        math.ceil(max(run.path_residual_m for run in runs) * 1000.0) / 1000.0,
        math.ceil(max(run.heading_residual_rad for run in runs) * 1e6) / 1e6,
    )
