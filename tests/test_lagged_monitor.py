"""The monitor deciding with an airframe's response (tssac_core.assurance.monitor.decide with a LaggedPrediction):
vehicles that fly the lagged model itself, under pilots that aim at the nearest radar or act at random, never come
nearer than the margin to a radar or the area's edge; the same pilots under the monitor that predicts with eq. 5
(the negative control) do. And the batched world's missions on airframes drawn from the F-16 response's spans
(fly_missions(airframes=...)): every adversary kept out, where eq. 5's monitor lets some in."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from tssac_core.assurance.lagged_backups import AirframeLag, LagState, lagged_rollout
from tssac_core.assurance.lagged_prediction import LaggedPrediction
from tssac_core.assurance.monitor import (
    KINEMATIC,
    EstimateError,
    Hazards,
    Limits,
    Memory,
    Prediction,
    Scene,
    ShieldConfig,
    decide,
    point_clearance,
)
from tssac_core.sim.adversaries import Adversary, AdversaryPilot
from tssac_core.sim.airframe_response import load_response
from tssac_core.sim.missions import fly_missions, mission_layout
from tssac_core.sim.scenario import load
from tssac_core.sim.varied_airframes import AirframeVariation

REPO = Path(__file__).resolve().parents[1]
DT = 0.1
W = math.radians(5.0)
AREA = 100_000.0
STEPS = 10  # a decision every second
DELAY = 2


def world(m: int, rng: np.random.Generator) -> tuple[Hazards, Limits, AirframeLag]:
    """Six radars per vehicle's world, the scenarios' limits, an F-16-like lag (no residual: the truth is the model)."""
    centres = rng.uniform(15_000.0, 85_000.0, (m, 6, 2))
    radii = rng.uniform(6_000.0, 12_000.0, (m, 6))
    lim = Limits(np.full(m, 150.0), np.full(m, 300.0), np.full(m, W), np.full(m, 10.0))
    air = AirframeLag(
        delay_steps=np.full(m, DELAY),
        tau_s=rng.uniform(1.1, 1.9, m),
        rollout_tau_s=rng.uniform(0.3, 1.3, m),
        accel_m_s2=np.full(m, 6.0),
        decel_m_s2=np.full(m, -2.0),
        residual_m=np.zeros(m),
    )
    return Hazards(centres, radii, AREA), lim, air


def pilots(x: np.ndarray, y: np.ndarray, phi: np.ndarray, hz: Hazards, rng: np.random.Generator) -> np.ndarray:
    """Half aim at the nearest radar's centre at full rate and full throttle; half act at random."""
    d = np.hypot(hz.centres_m[:, :, 0] - x[:, None], hz.centres_m[:, :, 1] - y[:, None]) - hz.radii_m
    k = np.argmin(d, axis=1)
    target = hz.centres_m[np.arange(len(x)), k]
    bearing = np.arctan2(target[:, 1] - y, target[:, 0] - x)
    off = (bearing - phi + math.pi) % (2 * math.pi) - math.pi
    aim = np.stack([np.clip(off / (W * 2.0), -1.0, 1.0), np.ones(len(x))], axis=1)
    random = rng.uniform(-1.0, 1.0, (len(x), 2))
    return np.where((np.arange(len(x)) % 2 == 0)[:, None], aim, random)


def fly(predict_with_lag: bool, seed: int, m: int = 60, seconds: float = 240.0) -> float:
    """Fly ``m`` vehicles of the lagged model under the monitor; return the least clearance any of them had."""
    rng = np.random.default_rng(seed)
    hz, lim, air = world(m, rng)
    cfg = ShieldConfig()
    margin = np.full(m, cfg.margin_m)
    x, y = rng.uniform(2_000.0, 98_000.0, m), rng.uniform(2_000.0, 98_000.0, m)
    v, phi = rng.uniform(150.0, 300.0, m), rng.uniform(-math.pi, math.pi, m)
    lag = LagState.steady(np.zeros(m), DELAY)
    # admitted starts only: some backup keeps the margin from there (the monitor's induction starts there)
    here = LaggedPrediction(air, lag).backup_excess(
        x, y, v, phi, EstimateError.zero(m), Scene(hz, lim, DT, margin, cfg)
    )
    keep = here.max(axis=1) >= 0
    assert keep.sum() >= m // 2
    idx = np.flatnonzero(keep)
    hz, lim, air, margin = hz.select(idx), lim.select(idx), air.select(idx), margin[idx]
    x, y, v, phi, lag = x[idx], y[idx], v[idx], phi[idx], lag.select(idx)
    n = len(idx)
    memory = Memory.initial(n)
    least = np.inf
    for _ in range(round(seconds / (STEPS * DT))):
        prediction: Prediction = LaggedPrediction(air, lag) if predict_with_lag else KINEMATIC
        state = np.stack([x, y, v, phi], axis=1)
        d = decide(state, pilots(x, y, phi, hz, rng), memory, hz, lim, DT, STEPS, margin, cfg, prediction=prediction)
        memory = d.memory
        commands = np.stack([d.action_at(k) for k in range(STEPS)], axis=1)  # (n, STEPS, 2)
        turn = np.clip(commands[:, :, 0], -1, 1) * W
        accel = np.clip(commands[:, :, 1], -1, 1) * 10.0
        path = lagged_rollout(x, y, v, phi, lag, turn, accel, air, lim, DT)
        least = min(least, float(point_clearance(path.xs, path.ys, hz).min()))
        x, y, v, phi = path.xs[:, -1], path.ys[:, -1], path.speeds[:, -1], path.headings[:, -1]
        lag = path.lag_after(STEPS)
    return least


def test_the_lagged_monitor_keeps_vehicles_of_the_lagged_model_out_and_the_eq5_monitor_does_not() -> None:
    margin = ShieldConfig().margin_m
    assert fly(True, seed=1, m=30, seconds=150.0) >= margin - 1e-6
    # the negative control: eq. 5's backups miss the airframe's paths, into a radar
    assert fly(False, seed=1, m=30, seconds=150.0) < 0.0


@pytest.mark.slow
@pytest.mark.parametrize("seed", [2, 3, 4, 5])
def test_the_lagged_monitor_keeps_them_out_for_five_minutes_on_more_worlds(seed: int) -> None:
    assert fly(True, seed=seed, m=60, seconds=300.0) >= ShieldConfig().margin_m - 1e-6


# ------------------------------------------------------------------- the batched world on varied F-16 airframes

LAYOUT_SEED = 4_400_000
"""random.yaml's layouts of this seed (the adversary tests' own range)."""


def batched_hazards(adversary: Adversary, missions: int, monitor_sees_airframes: bool) -> tuple[int, int, int]:
    """Fly ``missions`` of random.yaml (150 s) with every UAV an ``adversary``, on airframes drawn from the F-16
    response's spans (calm, no turbulence), through the monitor: UAV-missions with cost, UAVs out, unprotected steps."""
    from sim_vehicles.dynamics.response_fit import response_path

    variation = AirframeVariation.from_response(load_response(response_path("f16")))
    scenario = dataclasses.replace(load(REPO / "scenarios" / "random.yaml"), episode_steps=1500)
    layouts = [mission_layout(scenario, LAYOUT_SEED, k) for k in range(missions)]
    results = fly_missions(
        scenario, [AdversaryPilot(adversary)] * 3, 0, LAYOUT_SEED, layouts=layouts, shield=ShieldConfig(),
        airframes=variation, monitor_sees_airframes=monitor_sees_airframes,
    )  # fmt: skip
    assert results.monitor is not None
    return int((results.cost > 0).sum()), int(results.out_of_area.sum()), int(results.monitor.unprotected_steps.sum())


@pytest.mark.parametrize("adversary", [Adversary.AT_RADAR, Adversary.RANDOM], ids=str)
def test_on_varied_airframes_the_lagged_monitor_keeps_adversaries_out_and_eq5_does_not(adversary: Adversary) -> None:
    assert batched_hazards(adversary, 12, monitor_sees_airframes=True) == (0, 0, 0)
    with_cost, out, _ = batched_hazards(adversary, 12, monitor_sees_airframes=False)
    assert with_cost + out > 0  # the negative control: eq. 5's monitor on the same missions lets some in or out


@pytest.mark.slow
@pytest.mark.parametrize("adversary", list(Adversary), ids=str)
def test_on_varied_airframes_no_adversary_gets_in_on_forty_layouts(adversary: Adversary) -> None:
    assert batched_hazards(adversary, 40, monitor_sees_airframes=True) == (0, 0, 0)


def test_on_the_model_itself_a_held_lead_is_its_prediction_so_held_backups_fly_as_open_ones() -> None:
    """Calm air, airframes drawn from the F-16's spans, every UAV flying at a radar, the monitor offered only
    leads of 64 and 128 s: with the airframes' held leads (open for 32 s, then the line law) the backups fly exactly
    where the same leads flown open loop do (the lag model has no residual to correct: the line is its own path), so
    every mission's cost and time under the backup are the same, and the hold flew. An executor that held on past its
    lead's end (the turn never flown) let UAVs in here."""
    from sim_vehicles.dynamics.response_fit import response_path

    base = AirframeVariation.from_response(load_response(response_path("f16")))
    scenario = dataclasses.replace(load(REPO / "scenarios" / "random.yaml"), episode_steps=1500)
    layouts = [mission_layout(scenario, LAYOUT_SEED, k) for k in range(6)]
    runs = {}
    for held in ((64.0, 128.0), ()):
        variation = dataclasses.replace(base, held_leads_s=held)
        cfg = ShieldConfig(straight_leads_s=(64.0, 128.0))
        pilots = [AdversaryPilot(Adversary.AT_RADAR)] * 3
        runs[held] = fly_missions(scenario, pilots, 0, LAYOUT_SEED, layouts=layouts, shield=cfg, airframes=variation)
    held, open_ = runs[(64.0, 128.0)], runs[()]
    assert held.monitor is not None and open_.monitor is not None
    assert held.monitor.held_steps.sum() > 1000 and open_.monitor.held_steps.sum() == 0
    np.testing.assert_allclose(held.cost, open_.cost)
    np.testing.assert_array_equal(held.monitor.backup_steps, open_.monitor.backup_steps)
    assert held.out_of_area.sum() == 0
