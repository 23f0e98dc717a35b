"""Starts admitted by the prediction the monitor flies with (issue 58).

:func:`~tssac_core.sim.scenario.unprotected_start` admits a layout's starts by eq. 5's backups. A monitor that predicts
with an airframe's fitted response (``fly --shield --airframe-response FILE``) judges its first decision by that
response instead: its backups carry the airframe's lag and residual and, in wind, end in the ground loiter, whose
circle is wider. A start eq. 5 admits can lack clearance under that model, and then the first decision finds no clear
backup: the UAV flies unprotected until one clears. This module checks every start the way that first decision does:
after the link's round trip of the hold (straight on at constant speed: what the vehicle flies before the first
command reaches it, settled, its turn rate zero), the hold's path keeps the margin and some backup from its end keeps
it for ever, both after the error bound of :func:`~tssac_core.sim.scenario.start_error` and the turn rate's
at the first fix (:data:`STRAIGHT_START_TURN_SIGMA_RAD_S`). The SITL world and ``fly``
draw layouts with it, so the same seed gives both the same layout.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from tssac_core.assurance.ground_loiter import LoiterBound
from tssac_core.assurance.lagged_backups import LagState
from tssac_core.assurance.lagged_prediction import LaggedPrediction
from tssac_core.assurance.monitor import EstimateError, Scene, ShieldConfig
from tssac_core.sim.airframe_response import AirframeResponse, airframe_lag, load_response
from tssac_core.sim.scenario import ROLES, Layout, Scenario, StartCheck, start_error, start_problem, start_scene
from tssac_core.sim.varied_airframes import VariedAirframes
from tssac_core.sim.world import World

STRAIGHT_START_TURN_SIGMA_RAD_S = math.radians(0.1)
"""The standard deviation taken for a settled airframe's turn rate in straight flight, what a companion's filter starts
from at the first fix until a turn command reaches the vehicle: the F-16's stays below 0.01 deg/s for 10 s at every
speed of its envelope (tests/test_jsbsim_airframe.py), so 0.1 deg/s is a tenfold allowance."""


def lagged_start_excess_m(s: Scenario, lay: Layout, response: AirframeResponse, cfg: ShieldConfig) -> np.ndarray:
    """How far each UAV's start (decoy, detect, strike) lies inside what a monitor predicting with ``response``
    admits, (3,) metres; >= 0: admitted (module docstring)."""
    state, hz, lim = start_scene(s, lay)
    hold = round(2.0 * s.link.latency_ms / 1000.0 / s.dt_s)
    error = start_error(s, state[:, 2], cfg)
    promised = 0.0 if s.wind is None else s.wind.promised_max_m_s
    loiter = response.loiter_bound() if promised > 0.0 else None
    east, north = (0.0, 0.0) if s.wind is None else s.wind.velocity_m_s()
    lo, hi = response.speeds_m_s[0], response.speeds_m_s[-1]
    out = np.empty(len(ROLES))
    for i in range(len(ROLES)):  # one vehicle at a time: each has its own delay
        rows = np.array([i])
        x, y, v, phi = (state[rows, k] for k in range(4))
        airframe = airframe_lag(response, np.clip(v, lo, hi), s.dt_s)
        wind = None if loiter is None else loiter.wind(np.array([east]), np.array([north]), v)
        lag = LagState.steady(np.zeros(1), int(airframe.delay_steps[0]))
        prediction = LaggedPrediction(airframe, lag, wind)
        scene = Scene(hz.select(rows), lim.select(rows), s.dt_s, np.array([cfg.margin_m]), cfg)
        # The filter's turn rate at the first fix, as a heading error (the shield's turned term).
        turned = cfg.sigma_k * STRAIGHT_START_TURN_SIGMA_RAD_S * airframe.longest_tau_s()
        err = error.select(rows) + EstimateError(np.zeros(1), turned, np.zeros(1))
        if hold:
            hold_end = err.after(hold * s.dt_s, scene.lim)
            _, excess, _ = prediction.proposal_excess(x, y, v, phi, np.zeros((1, 2)), hold, hold_end, scene)
        else:
            excess = prediction.backup_excess(x, y, v, phi, err, scene).max(axis=1)
        out[i] = excess[0]
    return out


def lagged_start_check(s: Scenario, response: AirframeResponse, cfg: ShieldConfig | None = None) -> StartCheck:
    """The check :func:`~tssac_core.sim.scenario.sample_layout` takes (``start_check``): the first start a monitor
    predicting with ``response`` (margins of ``cfg``, default :class:`ShieldConfig`) cannot protect, or None."""
    shield = ShieldConfig() if cfg is None else cfg

    def check(lay: Layout) -> tuple[str, str] | None:
        for role, excess in zip(ROLES, lagged_start_excess_m(s, lay, response, shield), strict=True):
            if excess < 0:
                problem = start_problem(role, float(excess))
                return problem[0], f"{problem[1]} (predicting with the {response.aircraft}'s fitted response)"
        return None

    return check


def response_start_check(s: Scenario, response_path: Path | None) -> StartCheck | None:
    """:func:`lagged_start_check` for the response file the monitors predict with (``fly --airframe-response``, the
    SITL's ``monitor_response``), or None for monitors that predict with eq. 5. A file that does not read raises
    :class:`~tssac_core.sim.airframe_response.ResponseFileError` (one line)."""
    return None if response_path is None else lagged_start_check(s, load_response(response_path))


def varied_start_check(
    s: Scenario,
    world: World,
    varied: VariedAirframes,
    loiter: LoiterBound | None,
    index: int,
    cfg: ShieldConfig,
) -> StartCheck:
    """The further check of world ``index``'s starts in the batched world, where the monitor sees the airframes the
    vehicles fly (:class:`~tssac_core.sim.varied_airframes.VariedAirframes`, drawn for the world, straight and
    settled) and the world's wind, its backups ending in the ``loiter`` that bounds them there (None: calm air's
    turn): some backup from each start itself keeps the margin of ``cfg`` (the true state, no link: what the
    first decision finds when the proposal fails)."""
    flat = np.arange(len(ROLES)) + len(ROLES) * index
    airframe, lag = varied.airframe(flat), varied.lag_state(flat)
    east, north = (float(c) for c in world.wind_m_s()[:, index])
    n = len(ROLES)

    def check(lay: Layout) -> tuple[str, str] | None:
        state, hz, lim = start_scene(s, lay)
        x, y, v, phi = (state[:, k] for k in range(4))
        wind = None if loiter is None else loiter.wind(np.full(n, east), np.full(n, north), v)
        scene = Scene(hz, lim, s.dt_s, np.full(n, cfg.margin_m), cfg)
        excess = LaggedPrediction(airframe, lag, wind).backup_excess(x, y, v, phi, EstimateError.zero(n), scene)
        for role, best in zip(ROLES, excess.max(axis=1), strict=True):
            if best < 0:
                problem = start_problem(role, float(best))
                return problem[0], f"{problem[1]} (predicting with the airframe the mission flies)"
        return None

    return check
