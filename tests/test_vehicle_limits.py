"""What a vehicle achieves, as it publishes it (``ACHV_*`` parameters) and as the companion's monitor uses it: the
point mass publishes its limits, a JSBSim F-16 its airframe file's; the companion reads them over real UDP; a vehicle
that turns slower than the monitor's backups is refused before it arms; one that brakes weaker than eq. 5's braking
backups does not get them."""

from __future__ import annotations

import dataclasses
import math
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as M
from sitl_helpers import REPO, lockstep, scenario, sitl

from mavlink_bridge.companion.cli import build_companion
from mavlink_bridge.companion.config import CompanionConfig
from mavlink_bridge.companion.machine import Companion
from mavlink_bridge.companion.vehicle_limits import MonitorFit, monitor_fit, read_achievable
from mavlink_bridge.fly.report import achieved_text
from mavlink_bridge.link.connection import MavLink
from sim_vehicles.dynamics.jsbsim_airframe import AirframeError, load_airframe
from sim_vehicles.dynamics.jsbsim_dynamics import airframe_achievable
from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.sim.scenario import Dynamics, DynamicsModel, Role, Scenario, dump
from tssac_core.wire.vehicle_limits import Achievable, LimitParam

TURN = math.radians(5.0)


def test_an_f16_publishes_its_files_acceleration_and_braking_and_the_scenarios_turn() -> None:
    f16 = load_airframe("f16")
    achieved = airframe_achievable(f16, TURN, 10.0, 300.0)
    assert achieved == Achievable(5.0, f16.limits.max_accel_m_s2, -f16.limits.max_decel_m_s2)
    assert achieved.decel_max_m_s2 == pytest.approx(0.9)
    # A scenario that asks less than the airframe can do keeps its own limits.
    assert airframe_achievable(f16, TURN, 0.5, 300.0) == Achievable(5.0, 0.5, 0.5)


def test_a_turn_the_airframe_cannot_fly_at_top_speed_is_one_line() -> None:
    f16 = load_airframe("f16")  # 75 deg of bank: g tan(75 deg) / 300 m/s = 6.99 deg/s
    assert airframe_achievable(f16, math.radians(6.9), 10.0, 300.0).turn_rate_max_deg_s == pytest.approx(6.9)
    with pytest.raises(AirframeError) as refused:
        airframe_achievable(f16, math.radians(7.0), 10.0, 300.0)
    text = str(refused.value)
    assert "\n" not in text and "6.99 deg/s at 300 m/s" in text and "asks 7 deg/s" in text


def test_the_monitor_keeps_the_backups_the_vehicle_flies() -> None:
    assert monitor_fit(None, TURN, 10.0) == MonitorFit(None, True)  # it says nothing: the scenario's stand
    assert monitor_fit(Achievable(5.0, 10.0, 10.0), TURN, 10.0) == MonitorFit(None, True)
    # A float32 parameter is not the float64 limit to the last bit.
    assert monitor_fit(Achievable(float(np.float32(5.0 + 1e-7)) - 2e-6, 10.0, 9.99999), TURN, 10.0).braking_backups
    weak_brakes = monitor_fit(Achievable(5.0, 5.1, 0.9), TURN, 10.0)
    assert weak_brakes == MonitorFit(None, False)
    slow_turn = monitor_fit(Achievable(4.0, 10.0, 10.0), TURN, 10.0)
    assert slow_turn.refusal is not None and "at most 4 deg/s (ACHV_TURN_MAX)" in slow_turn.refusal
    assert "\n" not in slow_turn.refusal


@pytest.mark.parametrize("value", [0.0, -1.0, math.inf, math.nan])
def test_a_published_value_that_is_no_limit_is_refused(value: float) -> None:
    with pytest.raises(ValueError, match="decel_max_m_s2"):
        Achievable(5.0, 10.0, value)


def _read(port: int) -> tuple[Achievable | None, dict[str, float]]:
    with MavLink(f"udpout:127.0.0.1:{port}") as link:
        link.wait_heartbeat(5.0)
        achieved = read_achievable(link, 1.0, 2)
        mixed = link.read_params(["SIM_DT", "NO_SUCH_PARAM"], 0.5, 2)
        assert link.recv(1.0) is not None  # telemetry that arrived during the reads is still delivered
        return achieved, mixed


@pytest.mark.timeout(60)
def test_a_kinematic_vehicle_publishes_its_limits_over_udp() -> None:
    with sitl(speedup=5.0) as s:
        achieved, mixed = _read(s.ports[2])
        s.stop()
    assert achieved == Achievable(5.0, 10.0, 10.0)
    assert mixed == {"SIM_DT": pytest.approx(0.1)}  # an unknown name: a PARAM_ERROR, left out


@pytest.mark.timeout(120)
def test_a_jsbsim_f16_publishes_what_its_airframe_achieves_over_udp() -> None:
    scen = scenario(dynamics=Dynamics(DynamicsModel.JSBSIM, "f16"))
    with sitl(scen, **lockstep()) as s:
        achieved, _ = _read(s.ports[0])
        s.stop()
    assert achieved is not None
    assert (achieved.turn_rate_max_deg_s, achieved.decel_max_m_s2) == (pytest.approx(5.0), pytest.approx(0.9))
    assert achieved.accel_max_m_s2 == pytest.approx(load_airframe("f16").limits.max_accel_m_s2)
    assert not monitor_fit(achieved, TURN, 10.0).braking_backups


def test_the_report_says_what_the_vehicles_achieve() -> None:
    f16 = dataclasses.asdict(Achievable(5.0, 5.1, 0.9))
    assert achieved_text({"decoy": f16, "detect": f16}) == "every vehicle achieves 5 deg/s, +5.1 / -0.9 m/s/s"
    mixed = achieved_text({"decoy": f16, "strike": None})
    assert mixed.startswith("the decoy vehicle achieves") and "strike vehicle publishes no achievable limits" in mixed
    assert {p.value for p in LimitParam} <= {"ACHV_TURN_MAX", "ACHV_ACCEL_MAX", "ACHV_DECEL_MAX"}


def _companion(port: int, scen: Scenario, role: Role) -> Companion:
    return build_companion(
        CompanionConfig(
            f"udpout:127.0.0.1:{port}", role, scen, pilot="straight", shield=ShieldConfig(), connect_timeout_s=5.0
        )
    )


@pytest.mark.timeout(60)
def test_a_vehicle_that_turns_slower_than_the_backups_is_refused_before_it_arms() -> None:
    scen = scenario()
    with sitl(scen, speedup=5.0) as s:
        published = s.vehicle(0).params.get(LimitParam.TURN.value)
        published.value = 3.0  # this vehicle says it turns at most 3 deg/s
        result = _companion(s.ports[0], scen, Role.DECOY).run()
        armed = s.vehicle(0).armed
        s.stop()
    assert result.status == "refused" and result.exit_code != 0
    assert result.message == (
        "the vehicle turns at most 3 deg/s (ACHV_TURN_MAX): the monitor's backups turn at the scenario's 5 deg/s"
    )
    assert not armed and result.vehicle_limits == dataclasses.asdict(Achievable(3.0, 10.0, 10.0))


@pytest.mark.timeout(60)
def test_a_vehicle_that_brakes_weakly_gets_no_braking_backups() -> None:
    scen = scenario(episode_steps=600)
    with sitl(scen, speedup=20.0) as s:
        s.vehicle(2).params.get(LimitParam.DECEL.value).value = 0.9
        companion = _companion(s.ports[2], scen, Role.STRIKE)
        result = companion.run()
        s.stop()
    shield = companion.pilot_step.shield
    assert shield is not None and result.status != "refused", result.message
    assert result.vehicle_limits == pytest.approx(dataclasses.asdict(Achievable(5.0, 10.0, 0.9)))  # float32
    assert shield.cfg.braking_backups and not shield.monitor.cfg.braking_backups  # the negative control: the given cfg


@pytest.mark.timeout(120)
def test_fly_refuses_a_turn_the_airframe_cannot_fly_in_one_line(tmp_path: Path) -> None:
    base = scenario()
    fast = {role: dataclasses.replace(spec, turn_rate_max_deg_s=7.5) for role, spec in base.vehicles.items()}
    path = tmp_path / "fast-turns.yaml"
    dump(dataclasses.replace(base, vehicles=fast), path)
    out = tmp_path / "out.json"
    argv = ["--scenario", str(path), "--dynamics", "jsbsim", "--pilot", "straight", "--no-progress", "--json", str(out)]
    proc = subprocess.run(
        [sys.executable, "-m", "mavlink_bridge.fly", *argv], capture_output=True, text=True, timeout=100, cwd=REPO
    )
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert "f16: turns at most 6.99 deg/s at 300 m/s (bank limit 75 deg); the scenario asks 7.5 deg/s" in lines[0]
    assert not out.exists()


def test_a_stock_arduplanes_turn_is_its_bank_limit_at_its_top_airspeed() -> None:
    arduplane = {"ROLL_LIMIT_DEG": 45.0, "AIRSPEED_MAX": 22.0}  # ArduPlane's defaults
    achieved = Achievable.of(arduplane)
    assert achieved is not None and achieved.accel_max_m_s2 is None and achieved.decel_max_m_s2 is None
    assert achieved.turn_rate_max_deg_s == pytest.approx(math.degrees(9.80665 / 22.0))  # tan 45 = 1
    assert achieved.source == "ROLL_LIMIT_DEG 45 at AIRSPEED_MAX 22 m/s"
    assert Achievable.of({"ROLL_LIMIT_DEG": 45.0}) is None and Achievable.of({}) is None
    with pytest.raises(ValueError, match="bound no turn"):
        Achievable.of({"ROLL_LIMIT_DEG": 90.0, "AIRSPEED_MAX": 22.0})
    # At an F-16's speed its default bank gives 1.87 deg/s: a 5 deg/s scenario's backups cannot be flown.
    fast = Achievable.of({"ROLL_LIMIT_DEG": 45.0, "AIRSPEED_MAX": 300.0})
    refusal = monitor_fit(fast, TURN, 10.0).refusal
    assert refusal == (
        "the vehicle turns at most 1.87 deg/s (ROLL_LIMIT_DEG 45 at AIRSPEED_MAX 300 m/s): the monitor's backups turn "
        "at the scenario's 5 deg/s"
    )
    assert monitor_fit(achieved, TURN, 10.0) == MonitorFit(None, True)  # braking unknown: the scenario's stands
    assert Achievable.from_dict(dataclasses.asdict(achieved)) == achieved


@pytest.mark.timeout(30)
def test_the_companion_reads_a_stock_arduplanes_limits_over_udp() -> None:
    """A peer that answers as ArduPilot 4.6 does: PARAM_VALUE for its own parameters, PARAM_ERROR DOES_NOT_EXIST for
    the ACHV_* names it does not have."""
    own = {"ROLL_LIMIT_DEG": 45.0, "AIRSPEED_MAX": 22.0}
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(0.2)
    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    stop = threading.Event()

    def answer() -> None:
        asked = 0
        while not stop.is_set() and asked < 20:
            try:
                data, peer = vehicle.recvfrom(4096)
            except TimeoutError:
                continue
            for msg in mav.parse_buffer(data) or []:
                if msg.get_type() != "PARAM_REQUEST_READ":
                    continue
                asked += 1
                name = msg.param_id
                if name in own:
                    index = list(own).index(name)
                    reply = mav.param_value_encode(name.encode(), own[name], M.MAV_PARAM_TYPE_REAL32, len(own), index)
                else:
                    reply = mav.param_error_encode(255, 0, name.encode(), -1, M.MAV_PARAM_ERROR_DOES_NOT_EXIST)
                vehicle.sendto(reply.pack(mav), peer)

    responder = threading.Thread(target=answer, daemon=True)
    responder.start()
    try:
        with MavLink(f"udpout:127.0.0.1:{vehicle.getsockname()[1]}", target_system=1) as link:
            started = time.monotonic()
            achieved = read_achievable(link, 1.0, 3)
            took = time.monotonic() - started
    finally:
        stop.set()
        responder.join(2.0)
        vehicle.close()
    assert achieved == Achievable.of(own)
    assert took < 0.9  # every name answered at once: no attempt waited out its timeout
