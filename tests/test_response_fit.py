"""The airframe's fitted response (tssac_core/sim/airframe_response.py) and the tool that fits it from JSBSim
(sim_vehicles/dynamics/response_fit.py): the lag's equation, the fit on data of known parameters, the table's
lookup between speeds, the file's round trip and refusals, and the committed f16 file against JSBSim itself."""

from __future__ import annotations

import dataclasses
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sim_vehicles.dynamics.jsbsim_airframe import load_airframe
from sim_vehicles.dynamics.response_fit import (
    ROLLOUT_S,
    FitSettings,
    Turn,
    fit_lag,
    fly_turn,
    lag_rates,
    mean_accel,
    model_paths,
    refit_held,
    response_path,
    switched_lag_rates,
)
from tssac_core.sim.airframe_response import (
    AirframeResponse,
    ResponseFileError,
    dump_response,
    load_response,
)

DT_S = 0.1
W = math.radians(5.0)


def lag_by_recursion(before: float, command: float, steps: int, delay: int, tau_s: float) -> np.ndarray:
    """The response file's equation, one step at a time: omega_k+1 = omega_k + g (omega_cmd(k - d) - omega_k), the
    step flying the continuous lag's mean, integrated numerically here (1,000 points a step)."""
    g = 1.0 - math.exp(-DT_S / tau_s)
    t = (np.arange(1000) + 0.5) / 1000 * DT_S
    omega, rates = before, []
    for k in range(steps):
        target = before if k < delay else command
        rates.append(float(np.mean(target + (omega - target) * np.exp(-t / tau_s))))
        omega = omega + g * (target - omega)
    return np.array(rates)


@pytest.mark.parametrize("before, command, delay, tau_s", [(0.0, W, 0, 1.3), (-W, W, 3, 0.9), (W, -W, 7, 2.5)])
def test_closed_form_lag_equals_the_recursion(before: float, command: float, delay: int, tau_s: float) -> None:
    closed = lag_rates(before, command, 400, delay, np.array([tau_s]), DT_S)[0]
    np.testing.assert_allclose(closed, lag_by_recursion(before, command, 400, delay, tau_s), rtol=0, atol=1e-9)
    assert np.all(closed[:delay] == before) and closed[-1] == pytest.approx(command, abs=1e-6)


def test_the_switched_lag_rolls_out_with_its_own_time_constant_and_in_with_the_other() -> None:
    taus = np.array([1.3, 2.0])
    # one time constant both ways: the closed form
    np.testing.assert_allclose(
        switched_lag_rates(-W, W, 200, 2, np.array([1.3]), 1.3, DT_S), lag_rates(-W, W, 200, 2, np.array([1.3]), DT_S)
    )
    # a roll-out (less turn the same way, or none) follows the roll-out's time constant whatever the roll-in's
    out = switched_lag_rates(W, 0.0, 200, 1, taus, 0.4, DT_S)
    np.testing.assert_allclose(out, np.repeat(lag_rates(W, 0.0, 200, 1, np.array([0.4]), DT_S), 2, axis=0))
    # a roll-in, and a reversal through zero, follow the roll-in's
    for before in (0.0, -W):
        np.testing.assert_allclose(
            switched_lag_rates(before, W, 200, 1, taus, 0.4, DT_S), lag_rates(before, W, 200, 1, taus, DT_S)
        )


def synthetic_turn(
    before: float, command: float, delay: int, tau_s: float, rollout_tau_s: float = 0.6, speed: float = 250.0
) -> Turn:
    """A turn flown by the model itself (what a perfect fit must recover with no residual)."""
    skeleton = Turn(before, command, np.zeros(300), np.zeros((301, 2)), 0.3, speed)
    path = model_paths(skeleton, delay, np.array([tau_s]), DT_S, rollout_tau_s)[0]
    return dataclasses.replace(skeleton, xy_m=path)


TURNS = ((0.0, W), (0.0, -W), (-W, W), (W, -W))
ROLLOUTS = ((W, 0.0), (-W, 0.0))


def test_fit_recovers_a_known_delay_and_both_time_constants() -> None:
    turns = [synthetic_turn(b, c, 4, 1.7) for b, c in TURNS]
    rollouts = [synthetic_turn(b, c, 4, 1.7) for b, c in ROLLOUTS]
    fit = fit_lag(turns, rollouts, DT_S)
    assert (fit.delay_steps, fit.tau_s, fit.rollout_tau_s) == (4, pytest.approx(1.7), pytest.approx(0.6))
    assert fit.residual_m < 1e-6
    # negative control: the model one step late, or with another time constant, is metres off
    late = [synthetic_turn(b, c, 5, 1.7) for b, c in ((0.0, W), (-W, W))]
    assert fit_lag(late, [synthetic_turn(W, 0.0, 5, 1.7)], DT_S).delay_steps == 5
    error = turns[0].xy_m - model_paths(turns[0], 4, np.array([1.2]), DT_S, 0.6)[0]
    assert np.hypot(*error.T).max() > 50.0
    slow_out = rollouts[0].xy_m - model_paths(rollouts[0], 4, np.array([1.7]), DT_S, 1.7)[0]
    assert np.hypot(*slow_out.T).max() > 50.0  # a roll-out as slow as the roll-in is metres off too


def response(**changes: object) -> AirframeResponse:
    base = AirframeResponse(
        schema=2,
        aircraft="f16",
        airframe_sha256="0" * 64,
        jsbsim_version="1.3.3",
        command="test",
        altitude_m=5000.0,
        dt_s=0.1,
        turn_rate_max_rad_s=W,
        speeds_m_s=(150.0, 200.0, 300.0),
        turn_delay_s=(0.0, 0.3, 0.1),
        turn_tau_s=(1.8, 1.1, 0.9),
        turn_residual_m=(100.0, 200.0, 150.0),
        accel_max_m_s2=(8.0, 7.0, 5.0),
        decel_max_m_s2=(-1.0, -1.5, -3.0),
        accel_window_s=15.0,
        turn_rollout_tau_s=(0.9, 0.5, 0.2),
    )
    return dataclasses.replace(base, **changes)  # type: ignore[arg-type]


def test_a_speed_between_two_entries_interpolates_the_lag_and_takes_the_worse_bounds() -> None:
    r = response()
    at = r.at(250.0)  # halfway between 200 and 300 m/s
    assert (at.delay_s, at.tau_s, at.rollout_tau_s) == (pytest.approx(0.2), pytest.approx(1.0), pytest.approx(0.35))
    assert (at.turn_residual_m, at.accel_max_m_s2, at.decel_max_m_s2) == (200.0, 5.0, -1.5)
    own = r.at(200.0)  # a tabled speed: its own entry
    assert (own.delay_s, own.tau_s, own.rollout_tau_s, own.turn_residual_m) == (0.3, 1.1, 0.5, 200.0)
    assert (own.accel_max_m_s2, own.decel_max_m_s2) == (7.0, -1.5)
    worst = r.worst(150.0, 300.0)
    assert (worst.delay_s, worst.tau_s, worst.rollout_tau_s, worst.turn_residual_m) == (0.3, 1.8, 0.9, 200.0)
    assert (worst.accel_max_m_s2, worst.decel_max_m_s2) == (5.0, -1.0)
    assert at.delay_steps(DT_S) == 2 and at.lag_gain(DT_S) == pytest.approx(1 - math.exp(-0.1 / 1.0))
    with pytest.raises(ResponseFileError, match="outside the fitted span 150-300"):
        r.at(320.0)


def test_inconsistent_tables_are_refused() -> None:
    with pytest.raises(ValueError, match="one entry per speed"):
        response(turn_tau_s=(1.0, 1.0))
    with pytest.raises(ValueError, match="ascending"):
        response(speeds_m_s=(150.0, 300.0, 200.0))
    with pytest.raises(ValueError, match="decelerations < 0"):
        response(decel_max_m_s2=(-1.0, 0.5, -3.0))


LOITER = {
    "schema": 4,
    "turn_heading_residual_deg": (6.0, 4.0, 2.0),
    "loiter_wind_max_m_s": 10.0,
    "loiter_excursion_m": (5.0, 3.0, 4.0),
    "loiter_turn_in_s": 8.0,
    "loiter_residual_m": (30.0, 50.0, 40.0),
    "loiter_heading_residual_deg": (3.0, 1.0, 1.5),
}


def test_the_loiter_fit_round_trips_reads_between_speeds_and_older_files_fall_back(tmp_path: Path) -> None:
    path = tmp_path / "x.response.yaml"
    r = response(**LOITER)
    path.write_text(dump_response(r))
    assert load_response(path) == r
    assert r.at(250.0).loiter_excursion_m == 4.0  # between 200 and 300: the worse neighbour's
    bound = r.loiter_bound()
    assert bound is not None and bound.max_m_s == 10.0 and bound.law == r.loiter_law()
    assert bound.turn_in_s == 8.0 and bound.turn_in_steps(0.1) == 80 and bound.turn_in_steps(0.3) == 27
    windy = bound.wind(np.zeros(2), np.zeros(2), np.array([250.0, 150.0]))
    np.testing.assert_allclose(windy.heading_residual_rad, np.radians([1.5, 3.0]))  # the loiter's own, not the turns'
    np.testing.assert_allclose(windy.residual_m, [50.0, 30.0])
    assert windy.turn_in_s == 8.0
    # A version 3 file: the loiter starts where the lead ends, with the turns' residuals.
    three = {k: v for k, v in LOITER.items() if not k.startswith(("loiter_turn_in", "loiter_residual", "loiter_head"))}
    path.write_text(dump_response(response(**(three | {"schema": 3}))))
    old = load_response(path).loiter_bound()
    assert old is not None and old.turn_in_s == 0.0
    windy = old.wind(np.zeros(1), np.zeros(1), np.array([250.0]))
    np.testing.assert_allclose(windy.heading_residual_rad, [math.radians(4.0)])
    np.testing.assert_allclose(windy.residual_m, [max(response().turn_residual_m[1:])])
    path.write_text(dump_response(response()))  # a version 2 file: no loiter, no heading residual
    older = load_response(path)
    assert older.loiter_bound() is None and older.at(250.0).loiter_excursion_m is None
    with pytest.raises(ValueError, match="one entry per speed"):
        response(**(LOITER | {"loiter_excursion_m": (1.0, 2.0)}))
    with pytest.raises(ValueError, match="one entry per speed"):
        response(**(LOITER | {"loiter_residual_m": (1.0, 2.0)}))
    with pytest.raises(ValueError, match=">= 0"):
        response(**(LOITER | {"loiter_turn_in_s": -1.0}))


def test_a_wind_stronger_than_the_loiter_was_measured_in_is_refused() -> None:
    from tssac_core.sim.airframe_response import check_covers
    from tssac_core.sim.scenario import Wind, load

    repo = Path(__file__).resolve().parents[1]
    scenario = load(repo / "scenarios" / "random.yaml")
    fitted = response(**(LOITER | {"speeds_m_s": (150.0, 200.0, 300.0)}))
    check_covers(fitted, dataclasses.replace(scenario, wind=Wind(speed_m_s=10.0, from_deg=270.0)))
    with pytest.raises(ResponseFileError, match="measured in winds up to 10 m/s, the scenario promises 12 m/s"):
        check_covers(fitted, dataclasses.replace(scenario, wind=Wind(speed_m_s=8.0, from_deg=270.0, max_m_s=12.0)))
    with pytest.raises(ResponseFileError, match="calm air only"):
        check_covers(response(), dataclasses.replace(scenario, wind=Wind(speed_m_s=5.0, from_deg=0.0)))
    check_covers(response(), scenario)  # calm: no loiter needed


def test_file_round_trip_and_refusals(tmp_path: Path) -> None:
    path = tmp_path / "x.response.yaml"
    r = response()
    path.write_text(dump_response(r))
    assert load_response(path) == r
    version_1 = dump_response(r).replace("schema: 2", "schema: 1").split("turn_rollout_tau_s:")[0]
    path.write_text(version_1)  # before the roll-out's time constant: the roll-in's count both ways
    assert load_response(path).rollout_taus() == r.turn_tau_s
    path.write_text(dump_response(r).replace("schema: 2", "schema: 9"))
    with pytest.raises(ResponseFileError, match="newer than this program"):
        load_response(path)
    path.write_text(dump_response(r).replace("accel_window_s:", "accel_window: 3\naccel_window_s:"))
    with pytest.raises(ResponseFileError, match="unknown key"):
        load_response(path)
    airframe = tmp_path / "f16.yaml"
    airframe.write_text("model: f16\n")
    path.write_text(dump_response(r))
    with pytest.raises(ResponseFileError, match="fitted to another version of .*fit it again"):
        load_response(path, airframe)


@pytest.fixture(scope="module")
def f16_response() -> AirframeResponse:
    return load_response(response_path("f16"), response_path("f16").with_name("f16.yaml"))


def test_committed_f16_response_is_what_jsbsim_flies_at_250_m_s(f16_response: AirframeResponse) -> None:
    """The file's entry at 250 m/s against four fresh JSBSim turns, two roll-outs and two throttle runs (the full
    refit of every speed is ``python -m sim_vehicles.dynamics.response_fit --check``); halving either time constant,
    or adding a step of delay, makes the model's path farther from JSBSim's than the file's residual (the test can
    fail)."""
    spec = load_airframe("f16")
    i = f16_response.speeds_m_s.index(250.0)
    circles_s = 4.0 * math.pi / f16_response.turn_rate_max_rad_s
    turns = [fly_turn(spec, 250.0, f16_response.altitude_m, DT_S, b, c, circles_s) for b, c in TURNS] + [
        fly_turn(spec, 250.0, f16_response.altitude_m, DT_S, b, c, ROLLOUT_S) for b, c in ROLLOUTS
    ]
    delay = round(f16_response.turn_delay_s[i] / DT_S)
    tau, rollout_tau = f16_response.turn_tau_s[i], f16_response.turn_rollout_tau_s[i]

    def largest_distance(delay_steps: int, tau_s: float, rollout_tau_s: float) -> float:
        paths = [model_paths(t, delay_steps, np.array([tau_s]), DT_S, rollout_tau_s)[0] for t in turns]
        return max(float(np.hypot(*(t.xy_m - path).T).max()) for t, path in zip(turns, paths))

    residual = f16_response.turn_residual_m[i]
    assert largest_distance(delay, tau, rollout_tau) == pytest.approx(residual, abs=1e-3)
    assert largest_distance(delay, tau / 2, rollout_tau) > residual + 5.0
    assert largest_distance(delay, tau, rollout_tau * 3) > residual + 5.0
    assert largest_distance(delay + 3, tau, rollout_tau) > residual + 5.0
    accel = mean_accel(spec, 250.0, f16_response.altitude_m, DT_S, 10.0, f16_response.accel_window_s)
    decel = mean_accel(spec, 250.0, f16_response.altitude_m, DT_S, -10.0, f16_response.accel_window_s)
    assert (accel, decel) == (
        pytest.approx(f16_response.accel_max_m_s2[i], abs=1e-4),
        pytest.approx(f16_response.decel_max_m_s2[i], abs=1e-4),
    )
    # what JSBSIM.md measured before the work: it rolls in for about 2 s and cannot brake at 10 m/s^2; it rolls out
    # faster than it rolls in
    assert f16_response.turn_tau_s[i] + f16_response.turn_delay_s[i] > 0.5
    assert f16_response.turn_rollout_tau_s[i] < f16_response.turn_tau_s[i]
    assert -4.0 < decel < -1.0 and 4.0 < accel < 9.0


def test_check_refuses_a_response_of_another_airframe_version(tmp_path: Path) -> None:
    """``--check`` against an edited airframe file: one line, exit 2, before any flight."""
    airframe = tmp_path / "f16.yaml"
    shutil.copy(response_path("f16").with_name("f16.yaml"), airframe)
    shutil.copy(response_path("f16"), tmp_path / "f16.response.yaml")
    airframe.write_text(airframe.read_text().replace("settle_s: 5.0", "settle_s: 6.0"))
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "sim_vehicles.dynamics.response_fit",
            "--aircraft",
            str(airframe),
            "--check",
            "--speeds",
            "250",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "fitted to another version" in lines[0]


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--speeds", "300", "200"], "ascending"),
        (["--altitude-m", "0"], "altitude"),
        (["--held-after-s", "0.5"], "--held-after-s must be in [1, 120] s"),
        (["--held-after-s", "64"], "each in (64, 600] s"),
        (["--held-only"], "--held-only rewrites the held leads of a file"),
    ],
)
def test_bad_arguments_are_one_line_exit_2(argv: list[str], words: str) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "sim_vehicles.dynamics.response_fit", "--check", *argv],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2 and words in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_refitting_the_held_leads_alone_refuses_a_file_fitted_at_other_speeds(f16_response: AirframeResponse) -> None:
    """``--held-only`` keeps the file's turns: a file fitted at other speeds (or turn rate, altitude, step) than the
    command asks for is refused before anything flies."""
    settings = FitSettings(speeds_m_s=(150.0, 300.0), held_after_s=8.0, held_leads_s=(16.0, 64.0))
    with pytest.raises(ResponseFileError, match="fitted at speeds"):
        refit_held("f16", f16_response, settings, "test")
