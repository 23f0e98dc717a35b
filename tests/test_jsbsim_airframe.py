"""The JSBSim airframe and its inner loop, flown in JSBSim itself (sim_vehicles/dynamics/jsbsim_airframe.py).

Every flight here is deterministic (calm air, or a fixed seed) and short: the file takes a few seconds of CPU.
"""

from __future__ import annotations

import logging
import math
import subprocess
import sys
from pathlib import Path

import pytest

from sim_vehicles.dynamics.jsbsim_airframe import (
    AirframeError,
    AirframeSpec,
    AirframeState,
    JsbsimAirframe,
    StartState,
    Wind,
    load_airframe,
)
from tssac_core.sim.scenario import Turbulence

DT_S = 0.1
SPEED_M_S = 250.0
ALT_M = 5000.0
STEP_RATE_RAD_S = math.radians(5.0)


@pytest.fixture(scope="module")
def f16() -> AirframeSpec:
    return load_airframe("f16")


def fly(airframe: JsbsimAirframe, turn_rate_rad_s: float, accel_m_s2: float, duration_s: float) -> list[AirframeState]:
    return [airframe.step(turn_rate_rad_s, accel_m_s2, DT_S) for _ in range(round(duration_s / DT_S))]


def start_east(speed_m_s: float = SPEED_M_S) -> StartState:
    """Due east (heading 0 in the project frame) from (1 km, 2 km)."""
    return StartState(east_m=1000.0, north_m=2000.0, alt_m=ALT_M, speed_m_s=speed_m_s, heading_rad=0.0)


@pytest.fixture(scope="module")
def level_flight(f16: AirframeSpec) -> tuple[AirframeState, list[AirframeState]]:
    """60 s due east at 250 m/s under commands (0, 0), calm air: the state at step 0 and every step's."""
    with JsbsimAirframe(f16, start_east(), Wind(), 150.0, 300.0) as airframe:
        return airframe.state, fly(airframe, 0.0, 0.0, 60.0)


@pytest.fixture(scope="module")
def turn_step(f16: AirframeSpec) -> tuple[list[AirframeState], list[AirframeState]]:
    """2 s straight, then a heading-rate step to +5 deg/s (a LEFT turn) for 15 s, calm air, 250 m/s."""
    with JsbsimAirframe(f16, start_east(), Wind(), 150.0, 300.0) as airframe:
        return fly(airframe, 0.0, 0.0, 2.0), fly(airframe, STEP_RATE_RAD_S, 0.0, 15.0)


def test_straight_and_level_holds_altitude_and_speed(level_flight):
    """60 s of commands (0, 0) at 250 m/s: altitude within 30 m of the start's, airspeed within 2 m/s."""
    _, states = level_flight
    alt_error_m = max(abs(s.alt_m - ALT_M) for s in states)
    speed_error_m_s = max(abs(s.airspeed_m_s - SPEED_M_S) for s in states)
    assert alt_error_m < 30.0, alt_error_m
    assert speed_error_m_s < 2.0, speed_error_m_s
    assert max(abs(s.roll_rad) for s in states) < math.radians(1.0)


def test_flight_due_east_moves_east_by_v_t(level_flight):
    """Heading 0 (project frame) for 60 s: east by V * 60 within 1 %, north by less than 0.5 % of that; the
    position starts exactly at the start's."""
    first, states = level_flight
    assert (first.east_m, first.north_m) == (1000.0, 2000.0)
    assert first.course_rad == pytest.approx(0.0, abs=1e-3)
    assert first.yaw_rad == pytest.approx(math.pi / 2, abs=1e-3)  # MAVLink: east is 90 deg clockwise from north
    distance_m = SPEED_M_S * 60.0
    moved_east_m = states[-1].east_m - first.east_m
    moved_north_m = states[-1].north_m - first.north_m
    assert moved_east_m == pytest.approx(distance_m, rel=0.01)
    assert abs(moved_north_m) < 0.005 * distance_m


def test_position_integrates_the_ground_velocity(level_flight):
    """Each step's displacement matches the mean of its end groundspeeds along the course (trapezoid)."""
    _, states = level_flight
    for before, after in zip(states[:-1], states[1:]):
        v_east_m_s = 0.5 * sum(s.groundspeed_m_s * math.cos(s.course_rad) for s in (before, after))
        assert after.east_m - before.east_m == pytest.approx(v_east_m_s * DT_S, rel=1e-4)


@pytest.mark.parametrize("speed_m_s", [150.0, 300.0])
def test_a_settled_start_flies_straight(f16, speed_m_s):
    """From the settled start under commands (0, 0), calm air: the course rate stays below 0.01 deg/s for 10 s at the
    envelope's ends (what the companion's filter may start from at the first fix:
    tssac_core.sim.lagged_starts.STRAIGHT_START_TURN_SIGMA_RAD_S, 0.1 deg/s, allows ten times it)."""
    with JsbsimAirframe(f16, start_east(speed_m_s), Wind(), 150.0, 300.0) as airframe:
        states = [airframe.state, *fly(airframe, 0.0, 0.0, 10.0)]
    assert max(abs(math.degrees(s.turn_rate_rad_s)) for s in states) < 0.01


def test_heading_rate_step_settles(turn_step):
    """A heading-rate step 0 -> 5 deg/s, measured as the course rate (turn_rate_rad_s, calm air): t90 within
    3.5 s, overshoot below 10 %, steady-state error (last 5 s) below 0.1 deg/s; altitude within 30 m."""
    _, turning = turn_step
    rates_deg_s = [math.degrees(s.turn_rate_rad_s) for s in turning]
    t90_s = next(k for k, r in enumerate(rates_deg_s) if r >= 4.5) * DT_S + DT_S
    overshoot = (max(rates_deg_s) - 5.0) / 5.0
    steady_error_deg_s = sum(rates_deg_s[-50:]) / 50 - 5.0
    assert t90_s <= 3.5, t90_s
    assert overshoot < 0.10, overshoot
    assert abs(steady_error_deg_s) < 0.1, steady_error_deg_s
    assert max(abs(s.alt_m - ALT_M) for s in turning) < 30.0
    # a coordinated turn at 250 m/s and 5 deg/s banks atan(V omega / g) = 66 deg
    assert abs(math.degrees(turning[-1].roll_rad)) == pytest.approx(65.8, abs=3.0)


@pytest.mark.parametrize("speed_m_s", [150.0, 300.0])
def test_heading_rate_step_across_the_speed_envelope(f16, speed_m_s):
    """The same step at the envelope's ends (53 and 70 deg of bank): t90 within 3.5 s, overshoot below 10 %,
    steady-state error below 0.1 deg/s, altitude within 30 m."""
    with JsbsimAirframe(f16, start_east(speed_m_s), Wind(), 150.0, 300.0) as airframe:
        turning = fly(airframe, STEP_RATE_RAD_S, 0.0, 12.0)
    rates_deg_s = [math.degrees(s.turn_rate_rad_s) for s in turning]
    t90_s = next(k for k, r in enumerate(rates_deg_s) if r >= 4.5) * DT_S + DT_S
    assert t90_s <= 3.5, t90_s
    assert max(rates_deg_s) < 5.5
    assert abs(sum(rates_deg_s[-30:]) / 30 - 5.0) < 0.1
    assert max(abs(s.alt_m - ALT_M) for s in turning) < 30.0


def test_right_turn_step_mirrors_the_left(f16):
    """A step to -5 deg/s (a RIGHT turn): the same bounds as the left one, roll positive (right wing down). The
    f16 model's flaperons make rolling right lose lift, which the inner loop offsets (pitch_per_roll_stick);
    unoffset, this step overshot 31 %."""
    with JsbsimAirframe(f16, start_east(), Wind(), 150.0, 300.0) as airframe:
        turning = fly(airframe, -STEP_RATE_RAD_S, 0.0, 12.0)
    rates_deg_s = [-math.degrees(s.turn_rate_rad_s) for s in turning]
    t90_s = next(k for k, r in enumerate(rates_deg_s) if r >= 4.5) * DT_S + DT_S
    assert t90_s <= 3.5, t90_s
    assert (max(rates_deg_s) - 5.0) / 5.0 < 0.10, max(rates_deg_s)
    assert abs(sum(rates_deg_s[-30:]) / 30 - 5.0) < 0.1
    assert turning[-1].roll_rad == pytest.approx(math.radians(65.8), abs=math.radians(3.0))
    assert max(abs(s.alt_m - ALT_M) for s in turning) < 30.0


def test_declared_acceleration_limits_are_achievable(f16):
    """The file's worst cases hold: at least max_accel_m_s2 at full throttle from 300 m/s, and at least
    |max_decel_m_s2| of deceleration at no throttle from 150 m/s (means over 15 s, level)."""

    def mean_accel(speed_m_s: float, command_m_s2: float) -> float:
        with JsbsimAirframe(f16, start_east(speed_m_s), Wind(), 50.0, 500.0) as airframe:
            states = fly(airframe, 0.0, command_m_s2, 15.0)
        assert max(abs(s.alt_m - ALT_M) for s in states) < 50.0
        return (states[-1].airspeed_m_s - speed_m_s) / 15.0

    assert mean_accel(300.0, 50.0) >= f16.limits.max_accel_m_s2
    assert mean_accel(150.0, -50.0) <= f16.limits.max_decel_m_s2


def test_left_turn_is_positive_ccw_and_banks_left(turn_step):
    """A positive (LEFT) command: positive measured turn rate, course increasing counter-clockwise, roll negative
    (left wing down, MAVLink) and the MAVLink yaw (clockwise from north) decreasing."""
    straight, turning = turn_step
    later = turning[20:]
    assert all(s.turn_rate_rad_s > 0.0 for s in later)
    assert all(s.roll_rad < -math.radians(30.0) for s in later)
    assert all(math.remainder(b.course_rad - a.course_rad, math.tau) > 0.0 for a, b in zip(later[:-1], later[1:]))
    assert math.remainder(later[-1].yaw_rad - straight[-1].yaw_rad, math.tau) < -math.radians(30.0)
    # the turn rate is the course change: it integrates to the course (15 s at about 5 deg/s)
    turned_rad = sum(s.turn_rate_rad_s for s in turning) * DT_S
    assert turned_rad == pytest.approx(math.remainder(turning[-1].course_rad - straight[-1].course_rad, math.tau))
    assert math.degrees(turned_rad) == pytest.approx(75.0 - 2.5 * 5.0 / 2, abs=6.0)


def test_acceleration_command_changes_speed(f16):
    """+5 m/s^2 for 4 s then 0: the airspeed rises by about 20 m/s and holds it (the reference integrates the
    command); the reported acceleration is positive meanwhile."""
    with JsbsimAirframe(f16, start_east(200.0), Wind(), 150.0, 300.0) as airframe:
        speeding = fly(airframe, 0.0, 5.0, 4.0)
        holding = fly(airframe, 0.0, 0.0, 10.0)
    assert sum(s.accel_m_s2 for s in speeding) / len(speeding) > 3.0
    assert holding[-1].airspeed_m_s == pytest.approx(220.0, abs=1.0)
    assert speeding[-1].throttle > holding[-1].throttle


def test_identical_inputs_give_identical_states(f16):
    """Two airframes, same start and setpoints (turns both ways, speed changes), calm air: bit for bit equal."""
    commands = [(0.05, 2.0)] * 30 + [(-0.08, -3.0)] * 30 + [(0.0, 0.0)] * 20

    def run() -> list[AirframeState]:
        with JsbsimAirframe(f16, start_east(), Wind(), 150.0, 300.0, seed=7) as airframe:
            return [airframe.step(w, a, DT_S) for w, a in commands]

    first, second = run(), run()
    assert first == second
    assert len({s.east_m for s in first}) == len(first)  # it did fly


def test_turbulence_follows_the_seed(f16):
    """Moderate turbulence: the same seed gives the same flight, another seed another one."""

    def run(seed: int) -> list[AirframeState]:
        wind = Wind(speed_m_s=5.0, from_deg=90.0, turbulence=Turbulence.MODERATE)
        with JsbsimAirframe(f16, start_east(), wind, 150.0, 300.0, seed=seed) as airframe:
            return fly(airframe, 0.0, 0.0, 2.0)

    first, again, other = run(1), run(1), run(2)
    assert first == again
    assert [s.wind_east_m_s for s in first] != [s.wind_east_m_s for s in other]
    assert len({round(s.wind_north_m_s, 6) for s in first}) > 10  # gusts, not a steady wind


def test_jsbsim_banner_stays_off_stdout_in_a_fresh_process():
    """The wheel prints its banner once per process, at the first FDM: a fresh interpreter that creates an
    airframe (and a failing trim, which JSBSim complains about on stdout) writes only its own line there."""
    code = (
        "from sim_vehicles.dynamics.jsbsim_airframe import JsbsimAirframe, StartState, load_airframe\n"
        "spec = load_airframe('f16')\n"
        "JsbsimAirframe(spec, StartState(0.0, 0.0, 5000.0, 60.0, 0.0), speed_min_m_s=50.0).close()\n"
        "print('done')\n"
    )
    root = Path(__file__).resolve().parents[1]
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout == "done\n"
    assert "trim failed" in out.stderr  # the failing trim did run (and was logged to stderr)


def test_jsbsim_complaints_stay_off_stdout(f16, capfd, caplog):
    """Creating an airframe whose trim fails (60 m/s: JSBSim complains on stdout at every failed trim) prints
    nothing on stdout, Python's or file descriptor 1; what JSBSim said is logged at DEBUG; fd 1 works again."""
    capfd.readouterr()
    with caplog.at_level(logging.DEBUG, logger="sim_vehicles.dynamics.jsbsim_airframe"):
        JsbsimAirframe(f16, start_east(60.0), Wind(), 50.0, 300.0).close()
    print("after the airframe")
    out, _ = capfd.readouterr()
    assert out == "after the airframe\n"
    assert "trim failed" in caplog.text
    assert "JSBSim said: " in caplog.text and "trim" in caplog.text.split("JSBSim said: ")[1].lower()


def test_tailwind_adds_to_groundspeed(f16):
    """Wind from 270 deg (a westerly) at 10 m/s, flying east: groundspeed = airspeed + 10 m/s (within 1 m/s),
    wind_east_m_s = +10 (the air moves east), and the track stays east."""
    wind = Wind(speed_m_s=10.0, from_deg=270.0)
    assert wind.east_m_s == pytest.approx(10.0) and wind.north_m_s == pytest.approx(0.0, abs=1e-9)
    with JsbsimAirframe(f16, start_east(), wind, 150.0, 300.0) as airframe:
        states = [airframe.state, *fly(airframe, 0.0, 0.0, 10.0)]
    for s in states:
        assert s.groundspeed_m_s - s.airspeed_m_s == pytest.approx(10.0, abs=1.0)
        assert s.wind_east_m_s == pytest.approx(10.0, abs=0.1)
        assert s.wind_north_m_s == pytest.approx(0.0, abs=0.1)
        assert s.airspeed_m_s == pytest.approx(SPEED_M_S, abs=2.0)
    assert states[-1].east_m - states[0].east_m == pytest.approx(260.0 * 10.0, rel=0.01)


def test_crosswind_drifts_the_track_downwind(f16):
    """Wind from the north (0 deg) at 20 m/s, heading east: the air moves south, so the course is about
    -atan(20 / 250) (clockwise of east) while the heading stays east."""
    with JsbsimAirframe(f16, start_east(), Wind(speed_m_s=20.0, from_deg=0.0), 150.0, 300.0) as airframe:
        states = fly(airframe, 0.0, 0.0, 5.0)
    last = states[-1]
    assert last.wind_north_m_s == pytest.approx(-20.0, abs=0.1)
    assert last.course_rad == pytest.approx(-math.atan2(20.0, SPEED_M_S), abs=math.radians(0.5))
    assert last.yaw_rad == pytest.approx(math.pi / 2, abs=math.radians(1.0))
    assert last.north_m < 2000.0 - 15.0 * 5.0


def test_bad_inputs_and_closed_airframes_are_refused(f16):
    """dt must be a whole number of 120 Hz substeps, setpoints finite, winds and starts sane; a closed airframe
    refuses to step."""
    airframe = JsbsimAirframe(f16, start_east(), Wind(), 150.0, 300.0)
    with pytest.raises(ValueError, match="substeps"):
        airframe.step(0.0, 0.0, 0.105)
    with pytest.raises(ValueError, match="finite"):
        airframe.step(math.nan, 0.0, DT_S)
    with pytest.raises(ValueError, match="wind"):
        Wind(speed_m_s=-1.0)
    with pytest.raises(ValueError, match="start"):
        StartState(0.0, 0.0, math.inf, 250.0, 0.0)
    airframe.close()
    airframe.close()
    with pytest.raises(RuntimeError, match="closed"):
        airframe.step(0.0, 0.0, DT_S)
    with pytest.raises(ValueError, match="speed limits"):
        JsbsimAirframe(f16, start_east(320.0), Wind(), 150.0, 300.0)


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def f16_text(**replace: str) -> str:
    text = (Path(__file__).resolve().parents[1] / "sim_vehicles/dynamics/airframes/f16.yaml").read_text()
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new)
    return text


def test_the_bundled_f16_loads_with_its_limits(f16):
    """``f16`` names the bundled file: the wheel's f16 at 120 Hz, a 75 deg bank limit, an acceleration limit above
    0 and a deceleration limit below."""
    assert f16.model == "f16" and f16.physics_rate_hz == 120.0 and f16.root_dir is None
    assert f16.limits.bank_limit_deg == 75.0
    assert f16.limits.max_accel_m_s2 > 0.0 > f16.limits.max_decel_m_s2


def test_a_copy_by_path_loads_the_same_spec(f16, tmp_path):
    """A YAML path loads like the bundled name; a relative root_dir is taken from the file's directory."""
    copy = load_airframe(write(tmp_path / "f16.yaml", f16_text()))
    assert copy == f16
    (tmp_path / "models" / "aircraft" / "f16").mkdir(parents=True)
    (tmp_path / "models" / "aircraft" / "f16" / "f16.xml").write_text("<fdm_config/>\n")  # only looked for here
    moved = load_airframe(write(tmp_path / "mine.yaml", f16_text() + "root_dir: models\n").as_posix())
    assert moved.root_dir == (tmp_path / "models").resolve() and moved.name == "mine"
    assert moved.gains == f16.gains


@pytest.mark.parametrize(
    ("make", "expected"),
    [
        (lambda tmp: "f99", "unknown airframe 'f99'"),
        (lambda tmp: tmp / "missing.yaml", "no such airframe file"),
        (lambda tmp: write(tmp / "a.yaml", f16_text(**{"  bank_gain_1_s:": "  bank_gian_1_s:"})), "bank_gian_1_s"),
        (lambda tmp: write(tmp / "b.yaml", f16_text() + "colour: red\n"), "colour: unknown key"),
        (lambda tmp: write(tmp / "c.yaml", f16_text(**{"model: f16": "model: f99"})), "no JSBSim model 'f99'"),
        (lambda tmp: write(tmp / "d.yaml", f16_text(**{"settle_s: 5.0": "settle_s: fast"})), "settle_s: expected"),
        (lambda tmp: write(tmp / "e.yaml", "model: [f16\n"), "not valid YAML"),
        (lambda tmp: write(tmp / "f.yaml", "- f16\n"), "expected a mapping"),
        (lambda tmp: write(tmp / "g.yaml", f16_text(**{"bank_limit_deg: 75.0": "bank_limit_deg: 95.0"})), "(0, 90)"),
    ],
)
def test_bad_airframes_raise_one_line_errors(tmp_path, make, expected):
    """Unknown names, missing files, unknown or misspelt keys, bad values, bad YAML: AirframeError, one line,
    naming the culprit."""
    with pytest.raises(AirframeError) as caught:
        load_airframe(make(tmp_path))
    message = str(caught.value)
    assert expected in message
    assert "\n" not in message


def test_a_model_directory_that_does_not_load_raises(f16, tmp_path):
    """A root_dir whose f16.xml JSBSim cannot parse: AirframeError (one line) when the airframe is created."""
    model_dir = tmp_path / "models" / "aircraft" / "f16"
    model_dir.mkdir(parents=True)
    (model_dir / "f16.xml").write_text("<fdm_config><broken\n")
    spec = load_airframe(write(tmp_path / "f16.yaml", f16_text() + "root_dir: models\n"))
    with pytest.raises(AirframeError) as caught:
        JsbsimAirframe(spec, start_east(), Wind(), 150.0, 300.0)
    assert "cannot load model 'f16'" in str(caught.value)
    assert "\n" not in str(caught.value)
