"""ArduPlane's GUIDED dialect (``--setpoints arduplane``): the companion's commands field by field against pymavlink's
definitions, the SITL flying them as ArduPlane's GUIDED does, and whole missions in either dialect."""

from __future__ import annotations

import dataclasses
import json
import math
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from pymavlink import mavutil
from sitl_helpers import GUIDED, REPO, STRIKE, Client, sitl, wait_until

from mavlink_bridge.link import guided_commands
from mavlink_bridge.link.connection import MavLink
from mavlink_bridge.link.frames import Setpoint
from mavlink_bridge.link.guided_commands import slew_from_setpoint
from sim_vehicles.autopilot.modes import FlightMode
from tssac_core.sim.scenario import VehicleSpec, dump, load
from tssac_core.wire import units
from tssac_core.wire.lockstep import GRANT_NAME

M = mavutil.mavlink
SPEC = VehicleSpec()
LOITER = 12


def test_the_command_ids_are_pymavlinks() -> None:
    assert guided_commands.MAV_CMD_GUIDED_CHANGE_SPEED == M.MAV_CMD_GUIDED_CHANGE_SPEED == 43000
    assert guided_commands.MAV_CMD_GUIDED_CHANGE_HEADING == M.MAV_CMD_GUIDED_CHANGE_HEADING == 43002


@pytest.mark.parametrize(
    ("omega_deg_s", "accel", "heading_deg", "centripetal", "speed", "rate"),
    [
        (5.0, 0.0, 45.0 - 90.0 + 360.0, 250.0 * math.radians(5.0), 250.0, guided_commands.HOLD_SLEW_M_S2),
        (-2.0, 3.0, 45.0 + 90.0, 250.0 * math.radians(2.0), SPEC.speed_max_m_s, 3.0),
        (0.0, -4.0, 45.0, guided_commands.MIN_CENTRIPETAL_M_S2, SPEC.speed_min_m_s, 4.0),
    ],
)
def test_a_setpoint_as_arduplanes_commands(
    omega_deg_s: float, accel: float, heading_deg: float, centripetal: float, speed: float, rate: float
) -> None:
    """A left turn targets the course 90 deg to the left with the centripetal acceleration V omega; a right turn to
    the right; no turn the course itself at the smallest acceleration; the speed target is the limit the acceleration
    points at, slewed at |a|, or the speed held."""
    course = math.radians(45.0)  # north-east, CCW from east: compass 45 deg
    setpoint = Setpoint(units.yaw_rate_from_omega(math.radians(omega_deg_s)), accel)
    slew = slew_from_setpoint(setpoint, course, 250.0, SPEC)
    assert slew.heading_deg == pytest.approx(heading_deg % 360.0)
    assert slew.centripetal_m_s2 == pytest.approx(centripetal)
    assert (slew.speed_m_s, slew.slew_m_s2) == pytest.approx((speed, rate))


def test_without_an_estimate_the_heading_goes_back_to_the_autopilot() -> None:
    slew = slew_from_setpoint(Setpoint(0.05, 2.0), None, None, SPEC)
    assert slew.heading_deg is None and slew.speed_m_s is None


def test_the_datagram_matches_pymavlinks_definitions_field_by_field() -> None:
    """What the companion sends in the dialect, decoded by pymavlink: COMMAND_INT GUIDED_CHANGE_HEADING (param1
    course over ground, param2 the target heading, param3 the centripetal acceleration), COMMAND_INT
    GUIDED_CHANGE_SPEED (param1 airspeed, param2 the speed, param3 the acceleration), then the lockstep grant, all in
    one datagram addressed to the vehicle."""
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(5.0)
    link = MavLink(f"udpout:127.0.0.1:{vehicle.getsockname()[1]}", target_system=2)
    try:
        slew = slew_from_setpoint(Setpoint(units.yaw_rate_from_omega(0.05), -2.0), math.radians(30.0), 240.0, SPEC)
        assert link.send_guided_slew(slew, 12300, granted_through_ms=13200)
        data, _ = vehicle.recvfrom(4096)
    finally:
        link.close()
        vehicle.close()
    parser = mavutil.mavlink.MAVLink(None)
    msgs = parser.parse_buffer(data)
    assert [m.get_type() for m in msgs] == ["COMMAND_INT", "COMMAND_INT", "NAMED_VALUE_INT"]
    heading, speed, grant = msgs
    definition = M.enums["MAV_CMD"]
    assert "Course-over-ground" in definition[43002].param[1] and "centripetal" in definition[43002].param[3]
    assert heading.command == M.MAV_CMD_GUIDED_CHANGE_HEADING and heading.target_system == 2
    assert heading.param1 == M.HEADING_TYPE_COURSE_OVER_GROUND
    assert heading.param2 == pytest.approx((90.0 - 30.0 - 90.0) % 360.0, abs=1e-4)  # 0.05 rad/s left of 60 deg
    assert heading.param3 == pytest.approx(240.0 * 0.05, rel=1e-6)
    assert "Airspeed" in definition[43000].param[1] and "Acceleration" in definition[43000].param[3]
    assert speed.command == M.MAV_CMD_GUIDED_CHANGE_SPEED and speed.param1 == M.SPEED_TYPE_AIRSPEED
    assert (speed.param2, speed.param3) == pytest.approx((SPEC.speed_min_m_s, 2.0))
    assert grant.name == GRANT_NAME and (grant.time_boot_ms, grant.value) == (12300, 13200)


def _turn_rate_deg_s(
    c: Client, s, heading_deg: float, accel: float, speed: float, wall_s: float
) -> tuple[float, float]:
    """Send CHANGE_HEADING and CHANGE_SPEED for ``wall_s`` (as a companion keeps sending); the course's mean turn
    rate and acceleration over the last half of it."""
    v = s.vehicle(0)
    samples = []
    end = time.monotonic() + wall_s
    while time.monotonic() < end:
        c.mav.command_int_send(0, 0, 0, M.MAV_CMD_GUIDED_CHANGE_HEADING, 0, 0, 0, heading_deg, accel, 0, 0, 0, 0)
        c.mav.command_int_send(0, 0, 0, M.MAV_CMD_GUIDED_CHANGE_SPEED, 0, 0, 0, speed, 2.0, 0, 0, 0, 0)
        samples.append((s.runner.clock.sim_s, v.truth.phi_rad, v.truth.speed_m_s))
        c.collect(0.05)
    (t0, p0, v0), (t1, p1, v1) = samples[len(samples) // 2], samples[-1]
    return math.degrees(math.remainder(p1 - p0, 2 * math.pi)) / (t1 - t0), (v1 - v0) / (t1 - t0)


def test_the_sitl_flies_the_commands_as_arduplanes_guided() -> None:
    """A target far to the left turns left at a / V; one to the right, right; an acceleration of almost 0 flies
    straight; the speed slews at the commanded rate. Refusals as ArduPlane's: FAILED outside GUIDED or outside the
    airspeed limits, DENIED for a bad heading or speed type; a mode change forgets the commands."""
    with sitl(speedup=10.0) as s:
        c = Client(s.ports[0])
        c.connect()
        out = c.command(M.MAV_CMD_GUIDED_CHANGE_HEADING, 0, 90.0, 5.0)
        assert out is not None and out.result == M.MAV_RESULT_FAILED  # not in GUIDED yet
        c.arm()
        c.set_mode(GUIDED)
        v = s.vehicle(0)
        compass = (90.0 - math.degrees(v.truth.phi_rad)) % 360.0
        rate, accel = _turn_rate_deg_s(c, s, (compass - 90.0) % 360.0, 250.0 * math.radians(3.0), 250.0, 1.0)
        assert rate == pytest.approx(3.0, rel=0.01) and accel == 0.0
        compass = (90.0 - math.degrees(v.truth.phi_rad)) % 360.0
        rate, accel = _turn_rate_deg_s(c, s, (compass + 90.0) % 360.0, 250.0 * math.radians(2.0), 200.0, 1.0)
        assert rate < -1.9 and accel == pytest.approx(-2.0, rel=0.01)  # right, at a / V as V falls
        rate, _ = _turn_rate_deg_s(c, s, (compass + 90.0) % 360.0, 0.0, 200.0, 0.6)
        assert abs(rate) <= math.degrees(0.05 / 190.0)  # ArduPlane's floor of 0.05 m/s^2: 0.015 deg/s, straight
        for params, result in (
            ((0, 360.0, 5.0), M.MAV_RESULT_DENIED),
            ((7, 90.0, 5.0), M.MAV_RESULT_DENIED),
        ):
            ack = c.command(M.MAV_CMD_GUIDED_CHANGE_HEADING, *params)
            assert ack is not None and ack.result == result, params
        for params, result in (((1, 200.0, 1.0), M.MAV_RESULT_DENIED), ((0, 400.0, 1.0), M.MAV_RESULT_FAILED)):
            ack = c.command(M.MAV_CMD_GUIDED_CHANGE_SPEED, *params)
            assert ack is not None and ack.result == result, params
        assert v.setpoint is not None and v.setpoint.demand.heading_target is not None
        c.set_mode(LOITER)
        assert v.setpoint is None and v.mode is FlightMode.LOITER  # the commands are forgotten
        c.close()
        s.stop()


def test_a_silent_companions_heading_target_is_flown_on_as_arduplane_does() -> None:
    """ArduPlane's GUIDED has no timeout for a CHANGE_HEADING target (``mode_guided.cpp``): one command, then 15 s of
    simulated silence (15 times GUID_TIMEOUT), and the vehicle is still turning toward the target at a / V, with no
    failsafe and ACTIVE in its heartbeat. A setpoint of the other form, silent as long, is held straight (the
    setpoint-timeout failsafe): what a companion that stops must expect of each."""
    with sitl(speedup=10.0) as s:
        c = Client(s.ports[0])
        c.connect()
        c.arm()
        c.set_mode(GUIDED)
        v = s.vehicle(0)
        compass = (90.0 - math.degrees(v.truth.phi_rad)) % 360.0
        ack = c.command(M.MAV_CMD_GUIDED_CHANGE_HEADING, 0, (compass - 90.0) % 360.0, 250.0 * math.radians(3.0))
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        start = (s.runner.clock.sim_s, v.truth.phi_rad)
        beats = [m for m in c.collect(1.5) if m.get_type() == "HEARTBEAT" and m.get_srcComponent() == 1]
        turned = math.degrees(math.remainder(v.truth.phi_rad - start[1], 2 * math.pi))
        elapsed = s.runner.clock.sim_s - start[0]
        assert elapsed > 10.0 and not v.failsafe
        assert turned == pytest.approx(3.0 * elapsed * 250.0 / v.truth.speed_m_s, rel=0.1)  # still turning at a / V
        assert beats and all(b.system_status == M.MAV_STATE_ACTIVE for b in beats)
        c.setpoint(units.yaw_rate_from_omega(math.radians(3.0)), 0.0)  # a body-rate setpoint, then silence
        assert wait_until(lambda: v.failsafe, 2.0)
        held = v.truth.phi_rad
        c.collect(0.5)
        assert v.truth.phi_rad == pytest.approx(held)  # the failsafe holds heading
        c.close()
        s.stop()


def _fly(tmp: Path, name: str, scenario: Path, *extra: str) -> tuple[subprocess.CompletedProcess[str], dict]:
    out = tmp / name
    argv = [sys.executable, "-m", "mavlink_bridge.fly", "--scenario", str(scenario), "--no-progress"]
    argv += ["--json", str(out / "fly.json"), "--logs", str(out / "logs"), *extra]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=240, cwd=REPO)
    results = json.loads((out / "fly.json").read_text()) if (out / "fly.json").is_file() else {}
    return proc, results


@pytest.mark.sitl
def test_the_paper_mission_flies_alike_in_both_dialects(tmp_path: Path) -> None:
    """The shipped team on the paper's mission: the ArduPlane dialect flies it as the body rates do (same end, mission
    time within a second), and every one of its commands was accepted."""
    _, body = _fly(tmp_path, "body", STRIKE)
    proc, arduplane = _fly(tmp_path, "arduplane", STRIKE, "--setpoints", "arduplane")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert arduplane["setpoints"] == "arduplane" and body["setpoints"] == "body-rates"
    assert arduplane["success_rate"] == body["success_rate"] == 1.0
    assert arduplane["mean_mission_time_s"] == pytest.approx(body["mean_mission_time_s"], abs=1.0)
    statuses = [json.loads(p.read_text()) for p in (tmp_path / "arduplane" / "logs").rglob("*.status.json")]
    assert len(statuses) == 3 and all(s["counters"]["slew_acks"] > 200 for s in statuses)


@pytest.mark.sitl
def test_a_refused_command_is_one_line_and_the_vehicle_is_left_in_loiter(tmp_path: Path) -> None:
    """A companion whose scenario promises more speed than the vehicle flies asks for an airspeed the vehicle
    refuses (FAILED, as ArduPlane refuses one outside its limits): the companion says so in one line, leaves its
    vehicle in LOITER and exits 3; the world goes on."""
    s = load(STRIKE)
    faster = {k: dataclasses.replace(v, speed_max_m_s=320.0) for k, v in s.vehicles.items()}
    dump(dataclasses.replace(s, vehicles=faster), tmp_path / "faster.yaml")
    with sitl(s) as world:
        argv = [sys.executable, "-m", "mavlink_bridge.companion", "--connect", f"udpout:127.0.0.1:{world.ports[2]}"]
        argv += ["--role", "strike", "--pilot", "guidance", "--scenario", str(tmp_path / "faster.yaml")]
        argv += ["--setpoints", "arduplane", "--duration-s", "60"]
        proc = subprocess.run(argv, capture_output=True, text=True, timeout=120, cwd=REPO)
        vehicle = world.vehicle(2)
        assert proc.returncode == 3, proc.stderr
        said = "refused MAV_CMD_GUIDED_CHANGE_SPEED (MAV_RESULT_FAILED)"
        errors = [line for line in proc.stderr.splitlines() if "ERROR" in line]
        assert len(errors) == 1 and said in errors[0] and "left in LOITER" in errors[0], proc.stderr
        assert "status=refused" in proc.stdout and said in proc.stdout
        assert "Traceback" not in proc.stderr
        assert vehicle.mode is FlightMode.LOITER
        world.stop()
