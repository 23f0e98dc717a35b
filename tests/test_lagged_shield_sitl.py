"""The monitor predicting with the airframe's fitted response over MAVLink (``fly --shield --airframe-response``):
JSBSim F-16s under a pilot that turns at the nearest radar, flown by the companions against the SITL world in
lockstep, never enter it; the same pilot under the monitor that predicts with eq. 5 does (the negative control). And
the option's bad input: one line, exit 2, nothing written."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tssac_core.sim.scenario import dump, load

REPO = Path(__file__).resolve().parents[1]
RESPONSE = REPO / "sim_vehicles" / "dynamics" / "airframes" / "f16.response.yaml"


def fly(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mavlink_bridge.fly", *args, "--no-progress"],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        timeout=580,
    )


@pytest.fixture(scope="module")
def toward_a_radar(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The strike mission (its UAVs start heading at the radar at (38, 44) km), 150 s."""
    path = tmp_path_factory.mktemp("lagged") / "strike150.yaml"
    dump(dataclasses.replace(load(REPO / "scenarios" / "strike.yaml"), episode_steps=1500), path)
    return path


@pytest.mark.sitl
@pytest.mark.timeout(600)
@pytest.mark.parametrize("with_response", [True, False], ids=["airframe-response", "eq5"])
def test_at_radar_over_jsbsim_is_kept_out_by_the_lagged_monitor_and_not_by_eq5(
    toward_a_radar: Path, tmp_path: Path, with_response: bool
) -> None:
    out = tmp_path / "fly.json"
    extra = ["--airframe-response", str(RESPONSE)] if with_response else []
    proc = fly("--scenario", str(toward_a_radar), "--dynamics", "jsbsim", "--pilot", "at_radar", "--shield",
               "--json", str(out), *extra)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    results = json.loads(out.read_text())
    shield = results["shield"]
    assert shield["interventions_per_uav_mission"] >= 1 and shield["guarantee"] is False
    # Each vehicle said what its F-16 achieves (ACHV_*): eq. 5's braking backups were not offered to it.
    f16 = {"turn_rate_max_deg_s": 5.0, "accel_max_m_s2": 5.1, "decel_max_m_s2": 0.9}
    said = shield["vehicle_limits"]
    assert sorted(said) == ["decoy", "detect", "strike"] and all(
        v.pop("source") == "ACHV_TURN_MAX" for v in said.values()
    )
    assert said == {role: pytest.approx(f16) for role in said}
    assert "shield: every vehicle achieves 5 deg/s, +5.1 / -0.9 m/s/s" in proc.stdout
    if with_response:
        assert shield["uav_missions_with_cost"] == 0 and shield["uavs_left_area"] == 0, shield
        assert "airframe response f16.response.yaml" in shield["scope"]
        # The filter starts from the known straight start: no first fix's prior of 5 deg/s (a margin of ~5 km then),
        # and no control step without a clear backup.
        assert shield["max_margin_m"] < 2000.0 and shield["unprotected_time_fraction"] == 0.0, shield
    else:  # the negative control: eq. 5's backups miss the F-16's paths, into the radar
        assert shield["uav_missions_with_cost"] >= 1, shield


@pytest.fixture(scope="module")
def toward_a_radar_in_wind(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The same in a steady 10 m/s wind from the west, the response's fitted maximum."""
    from tssac_core.sim.scenario import Wind

    path = tmp_path_factory.mktemp("lagged-wind") / "strike150-wind.yaml"
    scenario = dataclasses.replace(load(REPO / "scenarios" / "strike.yaml"), episode_steps=1500)
    dump(dataclasses.replace(scenario, wind=Wind(speed_m_s=10.0, from_deg=270.0)), path)
    return path


@pytest.mark.sitl
@pytest.mark.timeout(600)
@pytest.mark.parametrize("with_response", [True, False], ids=["ground-loiter", "eq5"])
def test_in_wind_at_radar_over_jsbsim_is_kept_out_by_the_loiter_and_not_by_eq5(
    toward_a_radar_in_wind: Path, tmp_path: Path, with_response: bool
) -> None:
    """In wind the companions' backups end in the ground loiter (the vehicle's WIND reports, the law every tick): the
    F-16s stay out; the eq. 5 monitor's in the same wind let them in (the negative control)."""
    out = tmp_path / "fly.json"
    extra = ["--airframe-response", str(RESPONSE)] if with_response else []
    proc = fly("--scenario", str(toward_a_radar_in_wind), "--dynamics", "jsbsim", "--pilot", "at_radar", "--shield",
               "--json", str(out), *extra)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    shield = json.loads(out.read_text())["shield"]
    if with_response:
        assert shield["uav_missions_with_cost"] == 0 and shield["uavs_left_area"] == 0, shield
        assert "ground loiter" in shield["scope"] and shield["guarantee"] is False
    else:
        assert shield["uav_missions_with_cost"] >= 1, shield


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--dynamics", "jsbsim", "--airframe-response", str(RESPONSE)], "needs --shield"),
        (["--shield", "--airframe-response", str(RESPONSE)], "fly it with --dynamics jsbsim"),
        (["--shield", "--dynamics", "jsbsim", "--airframe-response", "/nonexistent.yaml"], "--airframe-response"),
    ],
)
def test_a_bad_airframe_response_is_one_line_and_nothing_written(args: list[str], words: str, tmp_path: Path) -> None:
    out = tmp_path / "fly.json"
    proc = fly("--scenario", str(REPO / "scenarios" / "short.yaml"), "--pilot", "straight", "--json", str(out), *args)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and words in lines[0], proc.stderr
    assert not out.exists()


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"speed_min_m_s": 100.0}, "fitted at 150-300 m/s, the scenario's decoy flies 100-300 m/s"),
        ({"turn_rate_max_deg_s": 3.0}, "turn-rate limit of 5 deg/s, the scenario's decoy turns at 3 deg/s"),
    ],
)
def test_a_response_that_does_not_cover_the_scenarios_vehicles_is_refused(
    change: dict[str, float], words: str, tmp_path: Path
) -> None:
    """Speeds the fit never flew, or another turn-rate limit: the response is no model of these vehicles."""
    scenario = load(REPO / "scenarios" / "short.yaml")
    vehicles = dict(scenario.vehicles, decoy=dataclasses.replace(scenario.vehicles["decoy"], **change))
    path, out = tmp_path / "other.yaml", tmp_path / "fly.json"
    dump(dataclasses.replace(scenario, vehicles=vehicles), path)
    proc = fly("--scenario", str(path), "--pilot", "straight", "--shield", "--dynamics", "jsbsim",
               "--airframe-response", str(RESPONSE), "--json", str(out))  # fmt: skip
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and words in lines[0], proc.stderr
    assert not out.exists()


def test_a_response_fitted_to_another_version_of_the_airframe_is_refused_by_the_world(tmp_path: Path) -> None:
    """The world flies an edited f16.yaml; the monitors' response was fitted to the shipped one: the world refuses
    before the mission, and fly says so in one line."""
    airframe = tmp_path / "f16.yaml"
    shipped = REPO / "sim_vehicles" / "dynamics" / "airframes" / "f16.yaml"
    airframe.write_text(shipped.read_text().replace("settle_s: 5.0", "settle_s: 6.0"))
    out = tmp_path / "fly.json"
    proc = fly("--scenario", str(REPO / "scenarios" / "short.yaml"), "--pilot", "straight", "--shield",
               "--dynamics", "jsbsim", "--aircraft", str(airframe), "--airframe-response", str(RESPONSE),
               "--json", str(out))  # fmt: skip
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "fitted to another version" in lines[0], proc.stderr
    assert not out.exists()
