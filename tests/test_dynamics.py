"""The physics seam (issue: real flight dynamics): the world's step split into integration and mission logic, the
scenario's wind and dynamics sections, and the SITL's kinematic backend."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from sim_vehicles.autopilot.telemetry import GRAVITY_M_S2
from sim_vehicles.dynamics.kinematic import KinematicDynamics
from tssac_core.sim.scenario import (
    DEFAULT_SCENARIO,
    SCENARIOS_DIR,
    Dynamics,
    DynamicsModel,
    ScenarioError,
    Turbulence,
    Wind,
    dump,
    from_dict,
    load,
    load_for_batched_world,
    sample_layout,
    to_dict,
)
from tssac_core.sim.world import StepResult, World

STEP_FIELDS = [f.name for f in dataclasses.fields(StepResult)]


def _worlds(scenario_file: str, n: int, seed: int) -> tuple[World, World]:
    s = load(SCENARIOS_DIR / scenario_file)
    rng = np.random.default_rng(seed)
    layouts = [sample_layout(s, rng) for _ in range(n)]
    a, b = World(s, n), World(s, n)
    a.reset(list(range(n)), layouts)
    b.reset(list(range(n)), layouts)
    return a, b


@pytest.mark.parametrize("scenario_file", ["random.yaml", "strike.yaml", "generalization.yaml", "corner.yaml"])
def test_states_handed_over_the_seam_give_the_steps_of_the_world_itself(scenario_file: str) -> None:
    """World B, given A's vehicle states after each integration (set_states) and judged by mission_step, equals A's
    own step bit for bit: every StepResult field and every state array, whole episodes, some worlds finishing early
    (parked vehicles and finished worlds keep their states)."""
    a, b = _worlds(scenario_file, n=16, seed=7)
    rng = np.random.default_rng(3)
    for _ in range(1500):
        action = rng.uniform(-1.3, 1.3, size=(16, 3, 2))
        ra = a.step(action)
        b.set_states(a.x_m.copy(), a.y_m.copy(), a.v_m_s.copy(), a.phi_rad.copy())
        rb = b.mission_step()
        for name in STEP_FIELDS:
            np.testing.assert_array_equal(getattr(ra, name), getattr(rb, name), err_msg=name)
        for name in ("x_m", "y_m", "v_m_s", "phi_rad", "cost_total", "steps", "running", "hit", "identified"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
        if not a.running.any():
            break
    assert (a.steps > 0).all()


def test_set_states_leaves_parked_vehicles_and_finished_worlds_alone() -> None:
    s = load(DEFAULT_SCENARIO)
    w = World(s, 2)
    lay = sample_layout(s, np.random.default_rng(1))
    w.reset([0, 1], [lay, lay], active=(True, False, True))
    w.running[1] = False
    w._update_moving()
    before = (w.x_m.copy(), w.y_m.copy(), w.v_m_s.copy(), w.phi_rad.copy())
    far = np.full((2, 3), 1234.5)
    w.set_states(far, far, far, np.full((2, 3), 4.0))  # 4 rad wraps to 4 - 2 pi
    assert w.x_m[0, 0] == 1234.5 and w.x_m[0, 2] == 1234.5 and w.phi_rad[0, 0] == pytest.approx(4.0 - 2 * math.pi)
    assert w.x_m[0, 1] == before[0][0, 1] and w.v_m_s[0, 1] == before[2][0, 1]  # parked
    np.testing.assert_array_equal(w.x_m[1], before[0][1])  # finished world
    np.testing.assert_array_equal(w.phi_rad[1], before[3][1])


def _straight_east(wind: Wind | None, steps: int = 100) -> World:
    s = dataclasses.replace(load(SCENARIOS_DIR / "strike.yaml"), wind=wind)
    w = World(s, 1)
    assert s.layout is not None
    starts = {k: dataclasses.replace(v, heading_deg=0.0) for k, v in s.layout.starts.items()}
    w.reset([0], [dataclasses.replace(s.layout, starts=starts)])
    for _ in range(steps):
        w.step(np.zeros((1, 3, 2)))
    return w


def test_wind_carries_the_vehicles_and_calm_is_eq5_bit_for_bit() -> None:
    """A west wind of 10 m/s adds 10 m/s to a flight due east (10 s: 100 m) and a south wind moves it north; a wind
    section of speed 0 flies bit for bit as no section (calm air is eq. 5 exactly)."""
    calm = _straight_east(None)
    zero = _straight_east(Wind(speed_m_s=0.0, from_deg=90.0))
    np.testing.assert_array_equal(calm.xy_m, zero.xy_m)
    west = _straight_east(Wind(speed_m_s=10.0, from_deg=270.0))
    assert west.x_m[0] - calm.x_m[0] == pytest.approx(np.full(3, 100.0))
    assert west.y_m[0] - calm.y_m[0] == pytest.approx(np.zeros(3), abs=1e-9)
    south = _straight_east(Wind(speed_m_s=10.0, from_deg=180.0))
    assert south.y_m[0] - calm.y_m[0] == pytest.approx(np.full(3, 100.0))
    np.testing.assert_array_equal(west.v_m_s, calm.v_m_s)  # v and phi stay the airspeed and heading


def test_wind_velocity_follows_the_pilots_convention() -> None:
    """``from_deg`` is where it blows from, clockwise from north: from the north moves the air south."""
    for from_deg, expected in ((0.0, (0.0, -5.0)), (90.0, (-5.0, 0.0)), (180.0, (0.0, 5.0)), (270.0, (5.0, 0.0))):
        assert Wind(5.0, from_deg).velocity_m_s() == pytest.approx(expected, abs=1e-12)


def test_scenario_wind_and_dynamics_round_trip(tmp_path) -> None:
    s = dataclasses.replace(
        load(SCENARIOS_DIR / "strike.yaml"),
        wind=Wind(12.0, 225.0, Turbulence.LIGHT, max_m_s=15.0),
        dynamics=Dynamics(DynamicsModel.JSBSIM, "f16"),
    )
    dump(s, tmp_path / "windy.yaml")
    assert load(tmp_path / "windy.yaml") == s
    text = (tmp_path / "windy.yaml").read_text()
    assert "turbulence: light" in text and "model: jsbsim" in text


def test_absent_sections_keep_every_scenarios_digest() -> None:
    """The new sections are optional: a scenario without them is the task it was (the shipped team's checkpoints
    record random.yaml's digest)."""
    from tssac_core.deploy.numpy_actor import load_actor

    shipped = load_actor(SCENARIOS_DIR.parent / "models" / "tssac" / "decoy.npz")
    assert load(DEFAULT_SCENARIO).digest() == shipped.meta["scenario_digest"]
    assert "wind" not in to_dict(load(DEFAULT_SCENARIO))


@pytest.mark.parametrize(
    ("section", "where"),
    [
        ({"wind": {"speed_m_s": 80.0}}, "wind.speed_m_s"),
        ({"wind": {"speed_m_s": 10.0, "from_deg": 360.0}}, "wind.from_deg"),
        ({"wind": {"speed_m_s": 10.0, "max_m_s": 5.0}}, "wind.max_m_s"),
        ({"wind": {"speed_m_s": 10.0, "max_m_s": 80.0}}, "wind.max_m_s"),
        ({"wind": {"speed_m_s": 45.0}}, "wind.speed_m_s"),  # half the slowest speed_min (150 m/s) is 75: fine...
        ({"wind": {"speed_m_s": 10.0, "turbulence": "severe"}}, "wind.turbulence"),
        ({"dynamics": {"model": "xplane"}}, "dynamics.model"),
        ({"dynamics": {"model": "jsbsim", "engine": "f100"}}, "dynamics.engine"),
    ],
)
def test_bad_wind_and_dynamics_sections_are_one_line(section: dict, where: str) -> None:
    data = {**to_dict(load(SCENARIOS_DIR / "strike.yaml")), **section}
    if section.get("wind", {}).get("speed_m_s") == 45.0:
        data["vehicles"] = {k: {**v, "speed_min_m_s": 80.0} for k, v in data["vehicles"].items()}  # ... not at 80
    with pytest.raises(ScenarioError) as err:
        from_dict(data, "bad.yaml")
    assert str(err.value).startswith(f"bad.yaml: {where}: ") and "\n" not in str(err.value)


def test_the_batched_world_refuses_a_jsbsim_scenario(tmp_path) -> None:
    s = dataclasses.replace(load(DEFAULT_SCENARIO), dynamics=Dynamics(DynamicsModel.JSBSIM))
    dump(s, tmp_path / "jsbsim.yaml")
    with pytest.raises(ScenarioError, match="dynamics.model: jsbsim flies only in the SITL"):
        load_for_batched_world(tmp_path / "jsbsim.yaml")
    dump(dataclasses.replace(s, dynamics=Dynamics()), tmp_path / "kinematic.yaml")
    assert load_for_batched_world(tmp_path / "kinematic.yaml").dynamics == Dynamics()


def _kinematic(wind: Wind | None) -> KinematicDynamics:
    s = dataclasses.replace(load(SCENARIOS_DIR / "strike.yaml"), wind=wind)
    w = World(s, 1)
    assert s.layout is not None
    w.reset([0], [s.layout])
    return KinematicDynamics(w)


def test_kinematic_truth_in_calm_air_is_the_commanded_turn_and_the_speed_change() -> None:
    """Calm air: omega as commanded (clipped to the limit), the speed change over dt, no air data (the telemetry
    derives bank and airspeed from the path as before)."""
    k = _kinematic(None)
    truths = k.advance(np.array([[[0.5, 1.0], [-2.0, -1.0], [0.0, 0.0]]]))
    limit = math.radians(5.0)
    assert [t.turn_rate_rad_s for t in truths] == [0.5 * limit, -limit, 0.0]
    assert [t.accel_m_s2 for t in truths] == pytest.approx([10.0, -10.0, 0.0])
    assert all(t.air is None for t in truths)


def test_kinematic_truth_in_wind_reports_ground_and_air_apart() -> None:
    """A 20 m/s wind from the south on a vehicle heading north-east: ground speed and course from air velocity plus
    wind, the airspeed and the nose's heading in the air data, and the wind itself."""
    k = _kinematic(Wind(20.0, 180.0))
    t = k.advance(np.array([[[0.0, 0.0]] * 3]))[0]
    assert t.air is not None
    v, phi = 250.0, math.radians(45.0)
    assert t.air.airspeed_m_s == v and t.air.heading_rad == pytest.approx(phi)
    assert t.speed_m_s == pytest.approx(math.hypot(v * math.cos(phi), v * math.sin(phi) + 20.0))
    assert t.phi_rad == pytest.approx(math.atan2(v * math.sin(phi) + 20.0, v * math.cos(phi)))
    assert (t.air.wind_east_m_s, t.air.wind_north_m_s) == pytest.approx((0.0, 20.0), abs=1e-12)
    turning = k.advance(np.array([[[-1.0, 0.0]] * 3]))[0]  # a right turn: right wing down, roll positive
    assert turning.air is not None
    assert turning.air.roll_rad == pytest.approx(math.atan(v * math.radians(5.0) / GRAVITY_M_S2))
    assert turning.turn_rate_rad_s < 0


def test_a_version_1_truth_log_still_reads_and_a_newer_one_is_refused(tmp_path) -> None:
    """A truth log written before the schema step (no ``schema``, rows without the measured turn rate) reads as it did;
    one from a newer writer is one clear error."""
    import json

    from mavlink_bridge.fly.mission_log import TruthLogError, read_mission

    row = {"x_m": 1.0, "y_m": 2.0, "v_m_s": 250.0, "phi_rad": 0.5, "cost": 0.0, "cost_total": 0.0, "omega_cmd": 0.0}
    row |= {"u_cmd": 0.0, "armed": True, "mode": "GUIDED", "failsafe": False}
    lines = [
        {"type": "header", "scenario": "strike", "seed": 0, "dt_s": 0.1, "roles": ["decoy", "detect", "strike"]},
        {"type": "step", "step": 1, "t_s": 0.1, "radar_on": False, "identified": False, "hit": False}
        | {"vehicles": {r: row for r in ("decoy", "detect", "strike")}},
        {"type": "summary", "success": False, "end": "stopped", "steps": 1, "sim_time_s": 0.1}
        | {"cost": {"decoy": 0.0, "detect": 0.0, "strike": 0.0}},
    ]
    old = tmp_path / "v1.jsonl"
    old.write_text("".join(json.dumps(line) + "\n" for line in lines))
    record = read_mission(old)
    assert record.steps == 1 and record.tracks_m["decoy"] == [(1.0, 2.0)]
    newer = tmp_path / "v9.jsonl"
    newer.write_text(
        "".join(json.dumps(line | ({"schema": 9} if i == 0 else {})) + "\n" for i, line in enumerate(lines))
    )
    with pytest.raises(TruthLogError, match="schema 9 is not one this reader knows"):
        read_mission(newer)


def test_evaluate_refuses_a_jsbsim_scenario_in_one_line(tmp_path, capsys) -> None:
    from tssac_core.common.cli import run
    from tssac_core.evaluate import main

    s = dataclasses.replace(load(DEFAULT_SCENARIO), dynamics=Dynamics(DynamicsModel.JSBSIM))
    dump(s, tmp_path / "jsbsim.yaml")
    argv = ["--scenario", str(tmp_path / "jsbsim.yaml"), "--controller", "guidance", "--episodes", "1"]
    assert run(main, argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "jsbsim flies only in the SITL" in err[0]
