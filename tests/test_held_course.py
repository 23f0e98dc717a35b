"""The law that holds a backup's lead on a ground line (tssac_core/assurance/held_course.py): its sign conventions,
and that it brings the lag model onto the line and keeps it there, from off the line and from the middle of a turn."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tssac_core.assurance.held_course import LineLaw, cross_track_m, line_turn_rate
from tssac_core.assurance.lagged_backups import AirframeLag, LagState, lag_gains, switched_lag_step

DT = 0.1
W = math.radians(5.0)


def test_left_of_the_line_is_positive_and_the_law_turns_back_toward_it() -> None:
    course = np.array([0.0])  # due east
    assert cross_track_m(np.array([10.0]), np.array([50.0]), np.zeros(1), np.zeros(1), course)[0] == 50.0
    law, limit = LineLaw(), np.full(1, W)
    ahead = (np.array([200.0]), np.zeros(1))  # flying east
    line = (np.zeros(1), np.zeros(1), course)
    left = line_turn_rate(np.zeros(1), np.array([500.0]), *ahead, line, limit, law)
    right = line_turn_rate(np.zeros(1), np.array([-500.0]), *ahead, line, limit, law)
    on = line_turn_rate(np.zeros(1), np.zeros(1), *ahead, line, limit, law)
    assert left[0] < 0.0 < right[0] and on[0] == 0.0  # a right turn (clockwise) from the left side


@pytest.mark.parametrize("offset_m", [0.0, 300.0, -800.0])
@pytest.mark.parametrize("rate", [0.0, W, -W])
def test_the_law_brings_the_lag_model_onto_the_line_and_keeps_it_there(offset_m: float, rate: float) -> None:
    """On the lag model at the slowest time constants of the F-16's spans: from off the line, and turning at the limit
    either way, the vehicle is on the line within a minute and stays there (how far it swings out on the way, on the
    airframe, is the fitted residual's business)."""
    air = AirframeLag(np.array([2]), np.array([1.6]), np.array([1.1]), np.array([5.0]), np.array([-1.0]), np.zeros(1))
    gains_in, gains_out = lag_gains(air.tau_s, DT), lag_gains(air.rollout_tau_s, DT)
    v = 250.0
    x, y, phi = np.zeros(1), np.array([offset_m]), np.zeros(1)
    lag = LagState.steady(np.array([rate]), 2)
    omega, pending = lag.omega_rad_s, list(lag.pending_rad_s[0])
    line = (np.zeros(1), np.zeros(1), np.zeros(1))
    errors = []
    for _ in range(1200):  # 120 s
        command = line_turn_rate(x, y, v * np.cos(phi), v * np.sin(phi), line, np.full(1, W), LineLaw())
        pending.append(float(command[0]))
        mean, omega = switched_lag_step(omega, np.array([pending.pop(0)]), gains_in, gains_out)
        half = 0.5 * mean * DT
        chord = v * DT * np.sinc(half / np.pi)
        x, y, phi = x + chord * np.cos(phi + half), y + chord * np.sin(phi + half), phi + mean * DT
        errors.append(float(cross_track_m(x, y, *line)[0]))
    assert max(abs(e) for e in errors[600:]) < 5.0  # on the line within a minute
    assert abs(errors[-1]) < 1.0
