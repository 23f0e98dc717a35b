"""Measure how far beyond its radius an airframe flies the ground loiter (:mod:`tssac_core.assurance.ground_loiter`):
in JSBSim under the airframe's inner loop, and on the airframe's lag model, from the worst states a backup's loiter
can start from, in calm air and in the declared maximum wind from every direction.

A run (:func:`fly_loiter`): the airframe flies ``ENTRY_HOLD_S`` at the entry's heading rate (a maximum-rate turn
against the loiter's direction, straight flight, or a maximum-rate turn its way), so its bank has settled; then the
loiter starts there, its circle sized for the maximum wind at the airframe's airspeed and its centre at R from the
vehicle on the turn's side of its ground track (:func:`~tssac_core.assurance.ground_loiter.loiter_centre`); the law
steers from the airframe's true position, ground velocity and wind every world step for ``laps`` laps. The lag model
flies the same loiter from the same state. A run's excursion is the larger of the two flights' largest distance
beyond the radius; the fit's, per speed, the largest of its runs (:func:`loiter_excursion_m`).

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
    fly_loiter_on_model,
    loiter_centre,
    loiter_radius_m,
    loiter_turn_rate,
)
from tssac_core.assurance.lagged_backups import AirframeLag, LagState, lag_gains, switched_lag_step

ENTRY_HOLD_S = 10.0
"""How long the entry's heading rate is held before the loiter starts: the f16's bank settles within 3 s."""
ENTRY_RATES = (-1.0, 0.0)
"""The heading rates the fit enters a loiter at, in turn-rate limits toward the loiter's turn: -1 a reversal at full
bank (the worst: the airframe keeps turning away while it rolls through), 0 from straight flight (every backup's lead
of 4 s or more ends straight). A maximum-rate turn its way enters inside the circle (``tests/test_ground_loiter.py``
flies it, and mid-roll states, against the fitted figure)."""
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
    and the loiter's direction (+1 counter-clockwise); optionally the start heading and a roll caught part-way (the
    entry's opposite rate commanded for ``reverse_steps`` world steps after the hold: mid-roll)."""

    speed_m_s: float
    wind: Wind
    entry: float
    sign: float
    heading_rad: float = START_HEADING_RAD
    reverse_steps: int = 0

    def entry_commands(self, turn_rate_max_rad_s: float, dt_s: float) -> list[float]:
        """The heading-rate commands flown before the loiter starts (rad/s)."""
        rate = self.entry * self.sign * turn_rate_max_rad_s
        return [rate] * round(ENTRY_HOLD_S / dt_s) + [-rate] * self.reverse_steps


@dataclass(frozen=True)
class LoiterRun:
    """What a run measured (m)."""

    case: LoiterCase
    radius_m: float
    airframe_excursion_m: float
    """The airframe's largest distance beyond the radius from the centre."""
    model_excursion_m: float
    """The lag model's, from the same state."""

    @property
    def excursion_m(self) -> float:
        return max(self.airframe_excursion_m, self.model_excursion_m)


def loiter_cases(speed_m_s: float, wind_max_m_s: float, directions: int = DIRECTIONS) -> list[LoiterCase]:
    """The fit's runs at one speed: calm air and ``wind_max`` from ``directions`` directions, each entry, both ways."""
    winds = [Wind()] + [Wind(speed_m_s=wind_max_m_s, from_deg=360.0 * k / directions) for k in range(directions)]
    if wind_max_m_s == 0.0:
        winds = winds[:1]
    return [LoiterCase(speed_m_s, w, e, s) for w, e, s in itertools.product(winds, ENTRY_RATES, (1.0, -1.0))]


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


def _ground(state: AirframeState) -> tuple[np.ndarray, np.ndarray]:
    speed, course = state.groundspeed_m_s, state.course_rad
    return np.array([speed * math.cos(course)]), np.array([speed * math.sin(course)])


def fly_loiter(
    spec: AirframeSpec,
    case: LoiterCase,
    lag: AirframeLag,
    wind_max_m_s: float,
    law: LoiterLaw,
    turn_rate_max_rad_s: float,
    altitude_m: float,
    dt_s: float,
    speed_limits_m_s: tuple[float, float],
    laps: float = LAPS,
) -> LoiterRun:
    """One run (module docstring): the airframe in JSBSim and ``lag`` (the airframe's model at the case's speed)."""
    entry = case.entry_commands(turn_rate_max_rad_s, dt_s)
    start = StartState(0.0, 0.0, altitude_m, case.speed_m_s, case.heading_rad)
    low, high = speed_limits_m_s
    limit = np.array([turn_rate_max_rad_s])
    with JsbsimAirframe(spec, start, wind=case.wind, speed_min_m_s=low, speed_max_m_s=high) as airframe:
        state = airframe.state
        for command in entry:
            state = airframe.step(command, 0.0, dt_s)
        x, y = np.array([state.east_m]), np.array([state.north_m])
        airspeed = np.array([state.airspeed_m_s])
        radius = loiter_radius_m(airspeed, wind_max_m_s, limit, law.authority)
        gx, gy = _ground(state)
        cx, cy = loiter_centre(x, y, gx, gy, case.sign, radius)
        steps = math.ceil(laps * 2.0 * math.pi * radius[0] / (airspeed[0] - wind_max_m_s) / dt_s)
        heading = np.array([math.pi / 2.0 - state.yaw_rad])  # MAVLink's yaw is clockwise from north
        model = fly_loiter_on_model(
            x, y, airspeed, heading, model_lag_after(entry, lag, dt_s),
            (case.wind.east_m_s, case.wind.north_m_s), (cx, cy), radius, case.sign, lag, limit, law, dt_s, steps,
        )  # fmt: skip
        far = -math.inf
        for _ in range(steps):
            gx, gy = _ground(state)
            here = np.array([state.east_m]), np.array([state.north_m])
            wind = state.wind_east_m_s, state.wind_north_m_s
            rate = loiter_turn_rate(*here, gx, gy, *wind, cx, cy, radius, case.sign, limit, law)
            state = airframe.step(float(rate[0]), 0.0, dt_s)
            far = max(far, math.hypot(state.east_m - cx[0], state.north_m - cy[0]) - radius[0])
    model_far = float((np.hypot(model.xs[0] - cx[0], model.ys[0] - cy[0]) - radius[0]).max())
    return LoiterRun(case, float(radius[0]), far, model_far)


def loiter_excursion_m(runs: Sequence[LoiterRun]) -> float:
    """The fit's excursion at a speed: the largest of its runs', rounded up to the millimetre."""
    return math.ceil(max(run.excursion_m for run in runs) * 1000.0) / 1000.0
