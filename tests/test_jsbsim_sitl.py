"""The JSBSim backend behind the SITL's MAVLink interface: whole missions flown by the shipped team over real UDP,
the telemetry an airframe reports (ATTITUDE, VFR_HUD, WIND), the truth log's measured turn rates, determinism, the
monitor's statement of its scope, and bad input."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil

from tssac_core.sim.scenario import Wind, dump, load
from tssac_core.wire.truth_log_schema import SCHEMA_VERSION, read_truth_log

# One test process runs this file: its module fixture (a JSBSim mission) is flown once.
pytestmark = [pytest.mark.sitl, pytest.mark.xdist_group("jsbsim_sitl")]

REPO = Path(__file__).resolve().parents[1]
STRIKE = REPO / "scenarios" / "strike.yaml"
SHORT = REPO / "scenarios" / "short.yaml"
"""A mission of about 12 s (strike.yaml's 250 s with the UAVs started in their rings): for the claims that do not
depend on the mission's length."""


def fly(tmp: Path, name: str, scenario: Path, *extra: str) -> tuple[subprocess.CompletedProcess[str], dict[str, Any]]:
    """One mission of the shipped team over MAVLink with JSBSim F-16s; its output and JSON."""
    out = tmp / name
    argv = ["--scenario", str(scenario), "--dynamics", "jsbsim", "--no-progress", "--full-telemetry"]
    argv += ["--logs", str(out / "logs"), "--tlog", str(out / "tlogs"), "--json", str(out / "fly.json"), *extra]
    proc = subprocess.run(
        [sys.executable, "-m", "mavlink_bridge.fly", *argv], capture_output=True, text=True, timeout=240, cwd=REPO
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc, json.loads((out / "fly.json").read_text())


def truth_log(tmp: Path, name: str) -> list[dict[str, Any]]:
    (path,) = (tmp / name / "logs").rglob("truth.jsonl")
    return read_truth_log(path)


def tlog_messages(tmp: Path, name: str, role: str, types: tuple[str, ...]) -> list[Any]:
    (path,) = (tmp / name / "tlogs").rglob(f"{role}.tlog")
    log = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    out = []
    while (msg := log.recv_match(type=list(types))) is not None:
        if msg.get_srcComponent() == 1:  # the vehicle's, not the companion's own
            out.append(msg)
    return out


@pytest.fixture(scope="module")
def calm(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any], str]:
    tmp = tmp_path_factory.mktemp("jsbsim")
    proc, results = fly(tmp, "calm", STRIKE)
    return tmp, results, proc.stdout


def test_the_shipped_team_flies_the_paper_mission_on_jsbsim_f16s(calm: tuple[Path, dict[str, Any], str]) -> None:
    """The paper's mission over MAVLink with three JSBSim F-16s: flown to the end, and the report, the JSON and the
    truth log's header say which dynamics flew."""
    tmp, results, stdout = calm
    assert results["episodes"] == 1 and results["error"] is None
    assert results["dynamics"] == {"model": "jsbsim", "aircraft": "f16"} and results["wind"] is None
    assert "dynamics: jsbsim f16, still air" in stdout
    header = truth_log(tmp, "calm")[0]
    assert header["schema"] == SCHEMA_VERSION and header["dynamics"] == {"model": "jsbsim", "name": "jsbsim f16"}
    assert results["success_rate"] == 1.0, results["missions"]


def test_attitude_reports_the_airframes_bank_and_the_log_its_measured_turns(
    calm: tuple[Path, dict[str, Any], str],
) -> None:
    """ATTITUDE's roll is the airframe's bank within 0.1 deg at every step the companion heard; the truth log's turn
    rate is the course's measured one (JSBSim's lag: it trails the command, and reaches at most the limit)."""
    tmp, _, _ = calm
    steps = {round(r["t_s"] * 1000): r for r in truth_log(tmp, "calm") if r["type"] == "step"}
    attitudes = tlog_messages(tmp, "calm", "decoy", ("ATTITUDE",))
    compared = 0
    for att in attitudes:
        row = steps.get(att.time_boot_ms)
        if row is None:
            continue
        air = row["vehicles"]["decoy"]["air"]
        assert math.degrees(abs(att.roll - air["roll_rad"])) < 0.1, (att.time_boot_ms, att.roll, air["roll_rad"])
        compared += 1
    assert compared > 1000
    rows = [r["vehicles"]["decoy"] for r in steps.values()]
    commanded = [r["omega_cmd"] * math.radians(5.0) for r in rows]
    measured = [r["turn_rate_rad_s"] for r in rows]
    assert max(abs(m) for m in measured) <= math.radians(5.0) * 1.1
    assert any(abs(m - c) > math.radians(0.5) for m, c in zip(measured, commanded))  # not the command echoed
    assert max(abs(r["air"]["alt_m"] - 5000.0) for r in rows) < 100.0


@pytest.mark.slow
def test_the_same_mission_twice_gives_the_same_truth_log(
    calm: tuple[Path, dict[str, Any], str], tmp_path: Path
) -> None:
    """Calm air, no turbulence: a second run of the same seed and scenario writes the same step lines, byte for byte
    (the order of the clients' handshake events at step 0 is the wall clock's)."""
    tmp, _, _ = calm
    fly(tmp_path, "again", STRIKE)

    def step_lines(root: Path) -> list[str]:
        (path,) = root.rglob("truth.jsonl")
        return [line for line in path.read_text().splitlines() if line.startswith('{"type":"step"')]

    first, second = step_lines(tmp / "calm"), step_lines(tmp_path / "again")
    assert len(first) > 2000 and first == second


def test_wind_shows_in_the_telemetry_and_the_monitor_says_it_is_no_guarantee(tmp_path: Path) -> None:
    """A 10 m/s south wind on the short mission (the UAVs fly north): ArduPilot's WIND message says so, VFR_HUD's
    airspeed and ground speed part, and a shielded run says the monitor's guarantee does not cover JSBSim in wind (in
    the report and the JSON), never that it does."""
    windy = tmp_path / "windy.yaml"
    dump(dataclasses.replace(load(SHORT), wind=Wind(speed_m_s=10.0, from_deg=180.0)), windy)
    proc, results = fly(tmp_path, "windy", windy, "--shield")
    assert results["wind"] == {"speed_m_s": 10.0, "from_deg": 180.0, "turbulence": "none"}
    assert results["shield"]["guarantee"] is False
    assert "covers the kinematic model (eq. 5) in still air, not jsbsim f16 dynamics and a 10 m/s wind" in proc.stdout
    winds = tlog_messages(tmp_path, "windy", "strike", ("WIND",))
    assert winds and all(abs(w.direction - 180.0) < 1.0 and abs(w.speed - 10.0) < 0.2 for w in winds)
    huds = tlog_messages(tmp_path, "windy", "strike", ("VFR_HUD",))  # flying north, downwind
    assert max(abs(h.groundspeed - h.airspeed) for h in huds) > 5.0


def test_an_unknown_airframe_is_one_line_and_nothing_written(tmp_path: Path) -> None:
    """An unknown airframe, a model directory JSBSim cannot load, and --aircraft without JSBSim: one line, exit 2, no
    JSON, from the world and from fly."""
    models = tmp_path / "models"
    models.mkdir()
    airframe = tmp_path / "jet.yaml"
    f16 = (REPO / "sim_vehicles" / "dynamics" / "airframes" / "f16.yaml").read_text()
    airframe.write_text(f16.replace("model: f16", f"model: f16\nroot_dir: {models}", 1))
    for argv in (
        ["-m", "sim_vehicles", "--scenario", str(STRIKE), "--dynamics", "jsbsim", "--aircraft", "nosuch"],
        ["-m", "mavlink_bridge.fly", "--scenario", str(STRIKE), "--dynamics", "jsbsim", "--aircraft", "nosuch"]
        + ["--no-progress", "--json", str(tmp_path / "out.json")],
        ["-m", "mavlink_bridge.fly", "--scenario", str(STRIKE), "--aircraft", "f16", "--json", str(tmp_path / "o")],
        ["-m", "mavlink_bridge.fly", "--scenario", str(STRIKE), "--dynamics", "jsbsim", "--aircraft", str(airframe)]
        + ["--no-progress", "--json", str(tmp_path / "out.json")],
    ):
        proc = subprocess.run([sys.executable, *argv], capture_output=True, text=True, timeout=60, cwd=REPO)
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and "error:" in lines[0] and "Traceback" not in proc.stderr, proc.stderr
        said = ("unknown airframe 'nosuch'", "--dynamics jsbsim", "no JSBSim model 'f16'")
        assert any(text in lines[0] for text in said), lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["jet.yaml", "models"]


def test_a_jsbsim_world_keeps_the_banner_off_its_stdout() -> None:
    """The world speaks to fly on stdout (its endpoints, ready, end): JSBSim's banner must not reach it."""
    proc = subprocess.run(
        [sys.executable, "-m", "sim_vehicles", "--scenario", str(SHORT), "--dynamics", "jsbsim", "--base-port", "0"]
        + ["--speedup", "1000", "--linger-s", "0"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO,
    )
    assert proc.returncode == 0, proc.stderr
    kinds = [line.split()[0] for line in proc.stdout.splitlines()]
    assert kinds == ["decoy", "detect", "strike", "ready", "end"], proc.stdout
    assert "dynamics=jsbsim" in proc.stdout
