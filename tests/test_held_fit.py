"""A backup whose lead holds its course, flown on JSBSim's F-16 from the middle of a reversal
(sim_vehicles/dynamics/held_fit.py): within the turns' residual of the monitor's prediction with the hold, far outside
it without (the negative control), and exactly the prediction on the lag model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sim_vehicles.dynamics.held_fit import HeldCase, fly_held
from sim_vehicles.dynamics.jsbsim_airframe import load_airframe
from sim_vehicles.dynamics.response_fit import response_path
from tssac_core.sim.airframe_response import airframe_lag, load_response

DT = 0.1


@pytest.fixture(scope="module")
def f16() -> tuple:
    response = load_response(response_path("f16"))
    return load_airframe("f16"), response


@pytest.mark.parametrize("speed", [200.0, 300.0])
def test_a_held_backup_from_a_reversal_keeps_to_its_prediction_and_an_open_one_does_not(
    f16: tuple, speed: float
) -> None:
    spec, response = f16
    lag = airframe_lag(response, np.array([speed]), DT)
    lag = dataclasses.replace(lag, held_residual_m=lag.residual_m, held_after_s=32.0)
    case = HeldCase(speed, -1.0, 1.0, 128.0, -1.0)  # a second into a reversal, a 128 s lead, then the turn
    held = fly_held(spec, case, lag, DT, 5000.0, (150.0, 300.0))
    open_ = fly_held(spec, case, lag, DT, 5000.0, (150.0, 300.0), law=None)
    residual = float(lag.residual_m[0])
    assert held.airframe_residual_m <= residual
    assert held.model_residual_m < 1.0  # on the model the hold is the prediction
    assert open_.airframe_residual_m > 2.0 * residual  # flown open, the lead's heading error grows without end
