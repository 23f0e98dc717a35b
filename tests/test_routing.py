"""Routing like a real vehicle (issue 59, item 3): the companion on the vehicle's system id with component 191, a
ground station on 255, both on one vehicle at once; each one's commands acknowledged to it alone, the companion
announced to the ground station as the vehicle's component; and MAVProxy on a second output watching a mission the
companions fly over serial lines."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from ground_station_helpers import MAVPROXY, MavProxyConsole, free_udp_port
from sitl_helpers import REPO, Client, sitl
from sitl_helpers import mavlink2 as M

from mavlink_bridge.companion import cli as companion_cli

SHORT = REPO / "scenarios" / "short.yaml"
ONBOARD = M.MAV_COMP_ID_ONBOARD_COMPUTER


def _onboard_heartbeat(c: Client) -> None:
    c.mav.heartbeat_send(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0, M.MAV_STATE_ACTIVE)


def test_companion_and_ground_station_on_one_vehicle_each_get_their_own_acks() -> None:
    """Companion 2:191 and ground station 255:190 on the detect UAV's port: each command's COMMAND_ACK goes to its
    sender only, addressed to its ids; the ground station sees the companion's heartbeat as component 191 of system
    2, and the companion never sees the ground station's."""
    with sitl() as s:
        port = s.ports[1]
        companion = Client(port, source_system=2, source_component=ONBOARD)
        gcs = Client(port, source_system=255, source_component=190)
        try:
            for c in (companion, gcs):
                assert c.connect().get_srcSystem() == 2
            companion.log.clear()
            gcs.log.clear()
            gcs.mav.command_long_send(
                2, 1, M.MAV_CMD_GET_MESSAGE_INTERVAL, 0, M.MAVLINK_MSG_ID_ATTITUDE, 0, 0, 0, 0, 0, 0
            )
            companion.mav.command_long_send(2, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            deadline = time.monotonic() + 3.0
            while time.monotonic() < deadline:
                _onboard_heartbeat(companion)
                gcs.heartbeat()
                companion.collect(0.1)
                gcs.collect(0.1)
            acks = {
                name: [(m.command, m.target_system, m.target_component) for m in c.log if m.get_type() == "COMMAND_ACK"]
                for name, c in (("companion", companion), ("gcs", gcs))
            }
            assert acks["companion"] == [(M.MAV_CMD_COMPONENT_ARM_DISARM, 2, ONBOARD)], acks
            assert acks["gcs"] == [(M.MAV_CMD_GET_MESSAGE_INTERVAL, 255, 190)], acks
            seen_by_gcs = {(m.get_srcSystem(), m.get_srcComponent()) for m in gcs.log if m.get_type() == "HEARTBEAT"}
            seen_by_companion = {
                (m.get_srcSystem(), m.get_srcComponent()) for m in companion.log if m.get_type() == "HEARTBEAT"
            }
            assert seen_by_gcs == {(2, 1), (2, ONBOARD)} and seen_by_companion == {(2, 1)}
            assert s.vehicle(1).armed and s.vehicle(1).counters.not_for_us == 0
        finally:
            companion.close()
            gcs.close()
        s.stop()


def test_the_source_system_is_the_vehicles_unless_given(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["--connect", "udpout:127.0.0.1:9", "--role", "decoy", "--pilot", "straight", "--scenario", str(SHORT)]
    assert companion_cli.main([*argv, "--source-system", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--source-system must be a MAVLink system id, 1 to 255, got 0" in err[0]


@pytest.mark.sitl
@pytest.mark.skipif(not MAVPROXY.exists(), reason="MAVProxy is a dev dependency (pip install -e .[dev])")
@pytest.mark.timeout(180)
def test_mavproxy_watches_a_mission_the_companions_fly_over_serial(tmp_path: Path) -> None:
    """The world with each vehicle on a 57,600-baud serial line and a ground-station output; fly's companions on the
    lines (``fly --connect DEVICE,BAUD ...``), MAVProxy on the output. MAVProxy detects each vehicle (N:1) and its
    companion as the vehicle's component 191 (N:191, not 255), sees GUIDED and the hit; the mission succeeds."""
    gcs_port = free_udp_port()
    world = subprocess.Popen(
        [sys.executable, "-m", "sim_vehicles", "--scenario", str(SHORT), "--base-port", "0", "--hold-start"]
        + ["--serial", "57600", "--out", f"udpout:127.0.0.1:{gcs_port}"],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    console = MavProxyConsole(gcs_port, tmp_path, master=f"udpin:127.0.0.1:{gcs_port}")
    try:
        assert world.stdout is not None
        lines = [world.stdout.readline().strip() for _ in range(4)]
        assert lines[-1].startswith("ready"), lines
        devices = [line.split()[2] for line in lines[:3]]
        assert all(d.startswith("/dev/") and d.endswith(",57600") for d in devices), devices
        for sysid in (1, 2, 3):
            assert console.wait_line(f"Detected vehicle {sysid}:1", 60.0) is not None, console.lines[-10:]
        fly = subprocess.run(
            [sys.executable, "-m", "mavlink_bridge.fly", "--scenario", str(SHORT), "--pilot", "straight"]
            + ["--connect", *devices, "--no-progress", "--json", str(tmp_path / "fly.json")],
            cwd=REPO,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert fly.returncode == 0, fly.stderr[-2000:]
        result = json.loads((tmp_path / "fly.json").read_text())
        assert result["missions"][0]["success"] is True
        for sysid in (1, 2, 3):
            assert console.wait_line(f"Detected vehicle {sysid}:{ONBOARD}", 10.0) is not None, console.lines[-20:]
        assert not any("Detected vehicle 255" in line for _, line in console.lines)
        assert console.wait_line("GUIDED", 10.0) is not None and console.wait_line("Target hit", 10.0) is not None
    finally:
        console.close()
        world.terminate()
        out, err = world.communicate(timeout=10)
    assert world.returncode == 0 and "end reason=success" in out, err[-2000:]
