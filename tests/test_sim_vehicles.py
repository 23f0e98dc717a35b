"""SITL vehicles over real UDP on 127.0.0.1 (OS-assigned ports), with pymavlink clients.

Most tests run a WorldRunner in a thread (tests/sitl_helpers.py); two start the command line as a
subprocess. Every wait is bounded and every test has a timeout.
"""

from __future__ import annotations

import dataclasses
import math
import os
import random
import select
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from sitl_helpers import GUIDED, MANUAL, REPO, STRIKE, Client, lockstep, mavlink2, mavutil, scenario, sitl, wait_until

from sim_vehicles.__main__ import main
from sim_vehicles.link.link_model import GpsReceiver, LinkChannel
from sim_vehicles.world_runner import WorldRunner
from tssac_core.sim.scenario import Layout, LinkModel, Origin, Radar, Start, load, sample_layout
from tssac_core.sim.sitl_config import SitlConfig
from tssac_core.sim.world import World
from tssac_core.wire.geodetic import (
    geodetic_to_local,
    heading_cdeg,
    local_to_geodetic,
    phi_from_yaw_ned,
    yaw_ned_from_phi,
)
from tssac_core.wire.signing import SigningKeyError, load_key
from tssac_core.wire.truth_log_schema import read_truth_log

M = mavlink2


# ------------------------------------------------------------------------------- pure models


def test_flat_earth_round_trip_and_frames() -> None:
    origin = Origin(47.397742, 8.545594, 5000.0)
    for east, north in [(0.0, 0.0), (100_000.0, 0.0), (0.0, 100_000.0), (12_345.6, 78_901.2)]:
        lat, lon = local_to_geodetic(origin, east, north)
        e2, n2 = geodetic_to_local(origin, lat, lon)
        assert e2 == pytest.approx(east, abs=1e-6) and n2 == pytest.approx(north, abs=1e-6)
    lat, _ = local_to_geodetic(origin, 0.0, 111_319.5)
    assert lat - origin.lat_deg == pytest.approx(1.0, abs=1e-4)  # one degree of latitude ~ 111.3 km
    # phi CCW from east -> yaw clockwise from north
    assert yaw_ned_from_phi(math.pi / 2) == pytest.approx(0.0)  # north
    assert yaw_ned_from_phi(0.0) == pytest.approx(math.pi / 2)  # east
    assert yaw_ned_from_phi(math.pi) == pytest.approx(-math.pi / 2)  # west
    assert heading_cdeg(0.0) == 9000 and heading_cdeg(math.pi / 2) == 0 and heading_cdeg(-math.pi / 2) == 18000
    for phi in np.linspace(-3.1, 3.1, 13):
        assert phi_from_yaw_ned(yaw_ned_from_phi(phi)) == pytest.approx(phi)


def test_link_channel_loss_duplication_latency_reordering() -> None:
    n = 20_000
    ch: LinkChannel[int] = LinkChannel(LinkModel(packet_loss=0.2, duplication=0.1), np.random.default_rng(0))
    for i in range(n):
        ch.push(0.0, i)
    got = ch.pop_due(0.0)
    assert ch.counters.lost / n == pytest.approx(0.2, abs=0.015)
    assert ch.counters.duplicated / (n - ch.counters.lost) == pytest.approx(0.1, abs=0.015)
    assert len(got) == n - ch.counters.lost + ch.counters.duplicated
    # latency: nothing before it, everything at it
    ch = LinkChannel(LinkModel(latency_ms=50.0), np.random.default_rng(0))
    ch.push(1.0, 7)
    assert ch.pop_due(1.049) == [] and ch.next_due_s() == pytest.approx(1.05)
    assert ch.pop_due(1.05) == [7]
    # reordering: a held datagram comes out right behind the next one
    ch = LinkChannel(LinkModel(reordering=1.0), np.random.default_rng(0))
    ch.push(0.0, 1)
    assert ch.pop_due(0.0) == []
    ch.push(0.0, 2)
    assert ch.pop_due(0.0) == [2, 1]
    ch.push(0.0, 3)  # held; released at the hold limit without a successor
    assert ch.pop_due(0.1) == [] and ch.pop_due(0.21) == [3]
    # seeded: two channels with the same seed behave identically
    runs = []
    for _ in range(2):
        ch = LinkChannel(
            LinkModel(packet_loss=0.3, reordering=0.2, duplication=0.2, latency_ms=5), np.random.default_rng(42)
        )
        out = []
        for i in range(200):
            ch.push(i * 0.001, i)
            out += ch.pop_due(i * 0.001)
        runs.append(out + ch.pop_due(10.0))
    assert runs[0] == runs[1]


def test_gps_receiver_rate_dropout_and_noise() -> None:
    gps = GpsReceiver(
        LinkModel(gps_rate_hz=5.0, gps_dropout_prob=0.25, gps_position_sigma_m=4.0, gps_velocity_sigma_m_s=0.5),
        np.random.default_rng(1),
    )
    fixes = [gps.sample(k * 0.1, 1000.0, 2000.0, 10.0, -5.0) for k in range(20_000)]
    due = gps.fixes + gps.dropouts
    assert due == 10_000  # every other 0.1 s step at 5 Hz
    assert gps.dropouts / due == pytest.approx(0.25, abs=0.015)
    east = np.array([f.east_m for f in fixes if f is not None])
    vn = np.array([f.vel_north_m_s for f in fixes if f is not None])
    assert east.mean() == pytest.approx(1000.0, abs=0.2) and east.std() == pytest.approx(4.0, rel=0.05)
    assert vn.mean() == pytest.approx(-5.0, abs=0.03) and vn.std() == pytest.approx(0.5, rel=0.05)


def test_signing_key_file_formats(tmp_path: Path) -> None:
    raw = bytes(range(32))
    (tmp_path / "raw.key").write_bytes(raw)
    (tmp_path / "hex.key").write_text(raw.hex() + "\n")
    (tmp_path / "bad.key").write_text("not a key\n")
    assert load_key(tmp_path / "raw.key") == raw
    assert load_key(tmp_path / "hex.key") == raw
    with pytest.raises(SigningKeyError, match="32 raw bytes or 64 hex"):
        load_key(tmp_path / "bad.key")
    with pytest.raises(SigningKeyError, match="cannot read"):
        load_key(tmp_path / "missing.key")


# ---------------------------------------------------------------------------------- telemetry


def _rate_hz(times_ms: list[int]) -> float:
    times = sorted(set(times_ms))
    return (len(times) - 1) / ((times[-1] - times[0]) / 1000.0)


@pytest.mark.timeout(30)
def _sim_span_s(msgs: list, name: str) -> float:
    """Simulated seconds between the first and the last ``name`` message (by their time_boot_ms)."""
    stamps = [m.time_boot_ms for m in msgs if m.get_type() == name]
    return (max(stamps) - min(stamps)) / 1000.0 if stamps else 0.0


def test_heartbeat_and_telemetry_at_their_rates_in_sim_time() -> None:
    scen = scenario()
    with sitl(scen, speedup=20.0) as s, Client(s.ports[1]) as c:
        hb = c.connect()
        assert hb.get_srcSystem() == 2 and hb.get_srcComponent() == 1
        assert hb.type == M.MAV_TYPE_FIXED_WING and hb.autopilot == M.MAV_AUTOPILOT_ARDUPILOTMEGA
        assert hb.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
        assert hb.custom_mode == MANUAL and hb.system_status == M.MAV_STATE_STANDBY
        msgs: list = []
        deadline = time.monotonic() + 15.0  # at 20x, 12 s of simulated time take 0.6 s; a loaded machine may be slower
        while time.monotonic() < deadline and _sim_span_s(msgs, "ATTITUDE") <= 12.0:
            msgs += c.collect(0.3)
        by_type: dict[str, list] = {}
        for m in msgs:
            by_type.setdefault(m.get_type(), []).append(m)
        span_s = _sim_span_s(msgs, "ATTITUDE")
        assert span_s > 12.0
        for name in ("ATTITUDE", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"):
            assert _rate_hz([m.time_boot_ms for m in by_type[name]]) == pytest.approx(10.0, rel=0.02), name
        # Messages without a timestamp are counted against the simulated span they arrived in.
        assert abs(len(by_type["VFR_HUD"]) - 10 * span_s) <= 2
        assert abs(len(by_type["HEARTBEAT"]) - span_s) <= 1.5
        assert _rate_hz([m.time_boot_ms for m in by_type["SYSTEM_TIME"]]) == pytest.approx(1.0, rel=0.05)
        assert abs(len(by_type["SYS_STATUS"]) - span_s) <= 1.5
        st = by_type["SYS_STATUS"][-1]
        gps = M.MAV_SYS_STATUS_SENSOR_GPS
        assert (
            st.onboard_control_sensors_present & gps
            and st.onboard_control_sensors_enabled & gps
            and st.onboard_control_sensors_health & gps
        )
        # GLOBAL_POSITION_INT and LOCAL_POSITION_NED describe the same (noise-free) fix
        lpn_at = {m.time_boot_ms: m for m in by_type["LOCAL_POSITION_NED"]}
        att_at = {m.time_boot_ms: m for m in by_type["ATTITUDE"]}
        gpi = next(
            m for m in reversed(by_type["GLOBAL_POSITION_INT"]) if m.time_boot_ms in lpn_at and m.time_boot_ms in att_at
        )
        lpn = lpn_at[gpi.time_boot_ms]
        east, north = geodetic_to_local(scen.origin, gpi.lat * 1e-7, gpi.lon * 1e-7)
        assert east == pytest.approx(lpn.y, abs=0.02) and north == pytest.approx(lpn.x, abs=0.02)
        assert gpi.vx == pytest.approx(lpn.vx * 100, abs=1) and gpi.vy == pytest.approx(lpn.vy * 100, abs=1)
        assert gpi.alt == gpi.relative_alt == int(scen.origin.alt_m * 1000)
        att_last = att_at[gpi.time_boot_ms]
        assert gpi.hdg == pytest.approx(math.degrees(att_last.yaw) % 360 * 100, abs=1)
        # SET_MESSAGE_INTERVAL: ATTITUDE to 2 Hz, VFR_HUD off
        ack = c.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, 500_000)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        ack = c.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_VFR_HUD, -1)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        c.collect(0.1)
        msgs = c.collect(0.8)
        att = [m.time_boot_ms for m in msgs if m.get_type() == "ATTITUDE"]
        assert _rate_hz(att) == pytest.approx(2.0, rel=0.05)
        assert not [m for m in msgs if m.get_type() == "VFR_HUD"]
        ack = c.command(M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        assert (
            c.wait_type("MESSAGE_INTERVAL", 1.0, message_id=M.MAVLINK_MSG_ID_ATTITUDE, interval_us=500_000) is not None
        )
        s.stop()


@pytest.mark.timeout(30)
def test_frames_of_one_step_share_a_datagram() -> None:
    # A step's telemetry (ATTITUDE, the two position messages, VFR_HUD...) leaves in one datagram per
    # client, every frame whole and valid, no datagram larger than COALESCE_BYTES unless it is one frame.
    from sim_vehicles.protocol.vehicle_link import COALESCE_BYTES

    with sitl(scenario(), speedup=20.0) as s, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sender = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
        sock.sendto(
            sender.heartbeat_encode(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(sender),
            ("127.0.0.1", s.ports[0]),
        )
        frames_per_datagram: list[int] = []
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline and len(frames_per_datagram) < 40:
            if not select.select([sock], [], [], 0.1)[0]:
                continue
            data = sock.recv(65535)
            parser = mavlink2.MAVLink(None)
            msgs = parser.parse_buffer(data) or []
            assert parser.buf_len() == 0, "a frame was cut"
            assert all(m.get_type() != "BAD_DATA" for m in msgs)
            assert len(msgs) == 1 or len(data) <= COALESCE_BYTES
            frames_per_datagram.append(len(msgs))
        s.stop()
    assert len(frames_per_datagram) >= 10
    assert np.median(frames_per_datagram) >= 4, frames_per_datagram


@pytest.mark.timeout(30)
def test_two_clients_share_a_vehicle_and_other_sysids_are_ignored() -> None:
    with (
        sitl(speedup=10.0) as s,
        Client(s.ports[0]) as gcs,
        Client(s.ports[0], source_system=1, source_component=191) as companion,
    ):
        gcs.connect()
        companion.connect()
        # Both receive the stream.
        assert gcs.wait_type("ATTITUDE", 1.0) is not None and companion.wait_type("ATTITUDE", 1.0) is not None
        assert len(s.endpoint(0).peers) == 2
        # A command for another system is not ours: no ACK, counted.
        before = s.vehicle(0).counters.not_for_us
        assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, target=7, timeout_s=0.3, retries=1) is None
        assert s.vehicle(0).counters.not_for_us > before and not s.vehicle(0).armed
        # The companion arms; the heartbeat both see says so.
        companion.arm(target=1)
        for client in (gcs, companion):
            assert (
                client.wait(
                    lambda m: m.get_type() == "HEARTBEAT" and bool(m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED), 2.0
                )
                is not None
            )
        s.stop()


# ------------------------------------------------------------------------------ commands


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.mark.timeout(30)
def test_a_listening_ground_station_on_out_gets_each_command_done_once_by_its_vehicle() -> None:
    """pymavlink's udpin side (MAVProxy's ``--master=udpin:``) writes every frame to all three vehicles: only the
    addressed one acts, and nothing is passed between vehicles (one ACK, one set of parameters)."""
    port = _free_port()
    gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, source_component=190)
    try:
        with sitl(speedup=5.0, outputs=(("127.0.0.1", port),)) as s:
            heard: set[int] = set()
            deadline = time.monotonic() + 10.0
            while (len(heard) < 3 or len(gcs.clients) < 3) and time.monotonic() < deadline:
                m = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=0.2)
                if m is not None:
                    heard.add(m.get_srcSystem())
            assert heard == {1, 2, 3} and len(gcs.clients) == 3
            gcs.mav.command_long_send(2, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            gcs.mav.param_request_list_send(2, 1)
            acks, values = [], []
            deadline = time.monotonic() + 2.0
            while time.monotonic() < deadline:
                m = gcs.recv_match(type=["COMMAND_ACK", "PARAM_VALUE"], blocking=True, timeout=0.1)
                if m is not None:
                    (acks if m.get_type() == "COMMAND_ACK" else values).append(m.get_srcSystem())
            assert acks == [2] and values == [2] * len(s.vehicle(1).params)
            assert s.vehicle(1).armed and not s.vehicle(0).armed and not s.vehicle(2).armed
            assert s.vehicle(1).counters.commands == 1
            assert s.vehicle(0).counters.not_for_us >= 2 and s.vehicle(2).counters.not_for_us >= 2
            s.stop()
    finally:
        gcs.close()


@pytest.mark.timeout(30)
def test_each_client_sees_consecutive_sequence_numbers_on_a_lossless_link() -> None:
    """Replies go to their requester only: with one sequence per destination, neither the requester nor the other
    client sees a gap (MAVProxy counts gaps as loss), and frames leave in the order of their numbers."""
    with sitl(speedup=5.0) as s, Client(s.ports[0]) as asking, Client(s.ports[0]) as watching:
        asking.connect()
        watching.connect()
        for client in (asking, watching):
            client.collect(0.3)
        seqs: dict[str, list[int]] = {"asking": [], "watching": []}
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline:
            asking.mav.command_long_send(
                1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, M.MAVLINK_MSG_ID_HOME_POSITION, 0, 0, 0, 0, 0, 0
            )
            asking.mav.param_request_read_send(1, 1, b"SIM_DT", -1)
            for name, client in (("asking", asking), ("watching", watching)):
                seqs[name] += [m.get_seq() for m in client.collect(0.05) if m.get_srcSystem() == 1]
        assert any(m.get_type() == "COMMAND_ACK" for m in asking.log)
        for name, got in seqs.items():
            gaps = [(a, b) for a, b in zip(got, got[1:]) if b != (a + 1) % 256]
            assert len(got) > 100 and not gaps, (name, gaps[:5])
        s.stop()


@pytest.mark.timeout(30)
def test_every_command_long_is_acknowledged() -> None:
    with sitl(speedup=5.0) as s, Client(s.ports[2]) as c:
        c.connect()
        cases = [
            ((M.MAV_CMD_COMPONENT_ARM_DISARM, 1), M.MAV_RESULT_ACCEPTED),
            ((M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 21196), M.MAV_RESULT_ACCEPTED),
            ((M.MAV_CMD_COMPONENT_ARM_DISARM, 2), M.MAV_RESULT_DENIED),
            ((M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED), M.MAV_RESULT_ACCEPTED),
            ((M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 10), M.MAV_RESULT_DENIED),  # AUTO
            ((M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, MANUAL), M.MAV_RESULT_ACCEPTED),
            ((M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION), M.MAV_RESULT_ACCEPTED),
            ((M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION), M.MAV_RESULT_ACCEPTED),
            ((M.MAV_CMD_REQUEST_MESSAGE, 9999), M.MAV_RESULT_UNSUPPORTED),
            ((M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1), M.MAV_RESULT_ACCEPTED),
            ((M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 50_000), M.MAV_RESULT_ACCEPTED),
            ((M.MAV_CMD_NAV_TAKEOFF,), M.MAV_RESULT_UNSUPPORTED),
            ((31010,), M.MAV_RESULT_UNSUPPORTED),  # a user command nobody implements
        ]
        for args, expected in cases:
            ack = c.command(*args)
            assert ack is not None, f"no COMMAND_ACK for {args}"
            assert ack.result == expected, (args, ack)
            assert ack.target_system == 255 and ack.target_component == 190
        version = next(m for m in c.log if m.get_type() == "AUTOPILOT_VERSION")
        for flag in (M.MAV_PROTOCOL_CAPABILITY_MAVLINK2, M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED):
            assert version.capabilities & flag
        home = next(m for m in c.log if m.get_type() == "HOME_POSITION")
        start = scenario().layout.starts["strike"].position_km
        lat, lon = local_to_geodetic(scenario().origin, start[0] * 1000, start[1] * 1000)
        assert home.latitude == round(lat * 1e7) and home.longitude == round(lon * 1e7)
        # The SET_MODE message is answered too (ArduPilot acks it with command = 11).
        c.mav.set_mode_send(3, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED)
        ack = c.wait_type("COMMAND_ACK", 1.0, command=M.MAVLINK_MSG_ID_SET_MODE)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        assert c.wait(
            lambda m: (
                m.get_type() == "HEARTBEAT"
                and m.custom_mode == GUIDED
                and bool(m.base_mode & M.MAV_MODE_FLAG_GUIDED_ENABLED)
            ),
            2.0,
        )
        # Ground-station chores: mission list, time sync.
        c.mav.mission_request_list_send(3, 1, M.MAV_MISSION_TYPE_MISSION)
        assert c.wait_type("MISSION_COUNT", 1.0, count=0) is not None
        c.mav.timesync_send(0, 123456)
        assert c.wait_type("TIMESYNC", 1.0, ts1=123456) is not None
        assert s.vehicle(2).counters.commands >= len(cases)
        s.stop()


@pytest.mark.timeout(30)
def test_pymavlink_ground_station_sees_names_arms_and_switches_mode() -> None:
    """The flow docs/mavlink.md shows: mavutil's own helpers and ArduPlane mode names work unchanged."""
    with sitl(speedup=5.0) as s:
        m = mavutil.mavlink_connection(f"udpout:127.0.0.1:{s.ports[2]}", source_system=255)
        try:
            m.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            assert m.wait_heartbeat(timeout=5) is not None
            assert m.target_system == 3 and m.flightmode == "MANUAL" and not m.motors_armed()
            m.arducopter_arm()
            m.set_mode("GUIDED")
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline and not (m.motors_armed() and m.flightmode == "GUIDED"):
                m.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
            assert m.motors_armed() and m.flightmode == "GUIDED"
            m.mav.set_position_target_local_ned_send(0, 3, 1, 12, 1087, 0, 0, 0, 0, 0, 0, 2.0, 0, 0, 0, -0.05)
            assert wait_until(lambda: s.vehicle(2).counters.setpoints_accepted == 1, 2.0)
        finally:
            m.close()
        s.stop()


@pytest.mark.timeout(30)
def test_parameter_protocol() -> None:
    with sitl(speedup=5.0) as s, Client(s.ports[1]) as c:
        c.connect()
        c.mav.param_request_list_send(2, 1)
        values = {}
        deadline = time.monotonic() + 3.0
        names = {
            "SYSID_THISMAV",
            "GUID_TIMEOUT",
            "SIM_DT",
            "SIM_TURN_MAX",
            "SIM_ACCEL_MAX",
            "SIM_SPD_MIN",
            "SIM_SPD_MAX",
        }
        names |= {"ACHV_TURN_MAX", "ACHV_ACCEL_MAX", "ACHV_DECEL_MAX", "ROLL_LIMIT_DEG", "AIRSPEED_MAX"}
        names |= {"WP_LOITER_RAD", "FS_GCS_ENABL", "FS_LONG_TIMEOUT", "FS_LONG_ACTN"}
        while time.monotonic() < deadline and len(values) < len(names):
            m = c.wait_type("PARAM_VALUE", 0.5)
            if m is not None:
                values[m.param_id] = m
        assert set(values) == names
        n = len(names)
        assert {m.param_count for m in values.values()} == {n} and sorted(
            m.param_index for m in values.values()
        ) == list(range(n))
        assert values["SYSID_THISMAV"].param_value == 2 and values["SYSID_THISMAV"].param_type == M.MAV_PARAM_TYPE_INT32
        assert values["SIM_TURN_MAX"].param_value == pytest.approx(5.0)
        assert values["ACHV_DECEL_MAX"].param_value == values["SIM_ACCEL_MAX"].param_value  # the point mass brakes so
        # A coordinated turn at 5 deg/s at the top speed, 300 m/s: 69.5 deg of bank.
        assert values["ROLL_LIMIT_DEG"].param_value == pytest.approx(69.46, abs=0.01)
        c.mav.param_request_read_send(2, 1, b"SIM_DT", -1)
        assert c.wait_type("PARAM_VALUE", 1.0, param_id="SIM_DT").param_value == pytest.approx(0.1)
        c.mav.param_set_send(2, 1, b"GUID_TIMEOUT", 2.5, M.MAV_PARAM_TYPE_REAL32)
        assert c.wait_type("PARAM_VALUE", 1.0, param_id="GUID_TIMEOUT").param_value == pytest.approx(2.5)
        assert s.vehicle(1).setpoint_timeout_s == pytest.approx(2.5)
        c.mav.param_set_send(2, 1, b"SYSID_THISMAV", 9, M.MAV_PARAM_TYPE_INT32)
        assert c.wait_type("PARAM_VALUE", 1.0, param_id="SYSID_THISMAV").param_value == 2
        assert c.wait(lambda m: False, 0.2) is None and any(
            m.get_type() == "STATUSTEXT" and "read-only" in m.text for m in c.log
        )
        s.stop()


@pytest.mark.timeout(30)
def test_a_refused_param_set_is_answered_at_once_as_ardupilot_does() -> None:
    """PARAM_ERROR first (MAVSDK ends its set with it), then the reason, complete, then the unchanged value."""
    with sitl(speedup=5.0) as s, Client(s.ports[0]) as c:
        c.connect()
        replies = ("PARAM_ERROR", "STATUSTEXT", "PARAM_VALUE")
        for name, value, error, text in (
            ("FS_LONG_TIMEOUT", 1000.5, M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE, "FS_LONG_TIMEOUT: 1000.5 not in 1..300"),
            ("WP_LOITER_RAD", -3e38, M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE, "WP_LOITER_RAD: -3e+38 not in 1..32767"),
            ("SIM_DT", 0.2, M.MAV_PARAM_ERROR_PERMISSION_DENIED, "SIM_DT is read-only"),
        ):
            c.mav.param_set_send(1, 1, name.encode(), value, M.MAV_PARAM_TYPE_REAL32)
            got = []
            while len(got) < 3 and (m := c.wait(lambda m: m.get_type() in replies, 1.0)) is not None:
                got.append(m)
            assert [m.get_type() for m in got] == list(replies), name
            assert got[0].error == error and got[0].param_id == name and got[1].text == text
            assert got[2].param_id == name and got[2].param_value == pytest.approx(s.vehicle(0).param(name))
        c.mav.param_set_send(1, 1, b"NO_SUCH_PARAM", 1.0, M.MAV_PARAM_TYPE_REAL32)
        err = c.wait_type("PARAM_ERROR", 1.0)
        assert err is not None and err.error == M.MAV_PARAM_ERROR_DOES_NOT_EXIST and err.param_id == "NO_SUCH_PARAM"
        s.stop()


def test_every_refusal_text_is_complete_and_fits_one_statustext() -> None:
    """Every text a refusal can make, over extreme values: at most 50 characters, so never cut."""
    from sim_vehicles.autopilot.modes import refusal
    from sim_vehicles.autopilot.params import vehicle_params
    from sim_vehicles.autopilot.setpoints import GLOBAL_REFUSAL, Refusal, parse_attitude_target, parse_position_target
    from sim_vehicles.protocol.commands import GOTO_REFUSAL, MISSION_UPLOAD_REFUSAL

    texts = [GOTO_REFUSAL, MISSION_UPLOAD_REFUSAL, GLOBAL_REFUSAL.text]
    names = [p.name for p in vehicle_params(1, 1.0, 0.1, 5.0, 2.0, 200.0, 300.0)]
    for name in names:
        for value in (1000.5, -3.4028235e38, 3.4028235e38, math.nan, math.inf, -0.000123456789, 123456789.0, 0.1):
            refused = vehicle_params(1, 1.0, 0.1, 5.0, 2.0, 200.0, 300.0).set(name, value)
            texts += [refused.text] if refused is not None else []
    texts += [refusal(m) for m in [*range(-1, 300), 2**31 - 1, 2**32 - 1]]
    mav = mavlink2.MAVLink(None)
    big = 3.4028235e38
    for frame in range(256):
        for mask in (0, 1087, 1479, 2503, 65535, 512 | 1087):
            for v in (0.0, big, math.nan):
                msg = mav.set_position_target_local_ned_encode(0, 1, 1, frame, mask, v, v, v, v, v, v, v, v, v, v, v)
                texts += [r.text for r in [parse_position_target(msg)] if isinstance(r, Refusal)]
    for mask in range(256):
        for v in (2.0, math.nan, -1.0):
            msg = mav.set_attitude_target_encode(0, 1, 1, mask, [1, 0, 0, 0], v, v, v, v)
            texts += [r.text for r in [parse_attitude_target(msg)] if isinstance(r, Refusal)]
    too_long = sorted({t for t in texts if len(t) > 50})
    assert not too_long and len(set(texts)) > 50, too_long
    assert "FS_LONG_TIMEOUT: 1000.5 not in 1..300" in texts and "FS_LONG_TIMEOUT: nan not in 1..300" in texts


# --------------------------------------------------------------------------------- setpoints


def _lockstep_round(c: Client, yaw_rate: float, accel: float, timeout_s: float = 3.0) -> int:
    """Send one setpoint stamped with the newest vehicle time; wait for the next step's tick."""
    ms = c.latest_ms
    c.setpoint(yaw_rate, accel, stamp_ms=ms)
    tick = c.wait(lambda m: m.get_type() == "SYSTEM_TIME" and m.time_boot_ms > ms, timeout_s)
    assert tick is not None, "the world did not step"
    return tick.time_boot_ms


@pytest.mark.timeout(30)
def test_guided_setpoints_fly_eq5_exactly(tmp_path: Path) -> None:
    scen = scenario()
    truth = tmp_path / "truth.jsonl"
    yaw_rate, accel = -0.04, 4.0  # a left (CCW) turn at 0.04 rad/s, speeding up at 4 m/s^2
    yaw_rate2, accel2 = 1.0, -50.0  # beyond the limits: clipped to 5 deg/s right, -10 m/s^2
    n1, n2 = 40, 20
    with sitl(scen, truth_log=truth, **lockstep()) as s, Client(s.ports[0]) as c:
        c.connect()
        c.arm()
        assert c.set_mode(GUIDED).result == M.MAV_RESULT_ACCEPTED
        for _ in range(n1):
            ms = _lockstep_round(c, yaw_rate, accel)
        for _ in range(n2):
            ms = _lockstep_round(c, yaw_rate2, accel2)
        assert ms == (n1 + n2) * 100
        c.collect(0.2)  # the rest of the last step's telemetry
        lpn = next(m for m in c.log if m.get_type() == "LOCAL_POSITION_NED" and m.time_boot_ms == ms)
        att = next(m for m in c.log if m.get_type() == "ATTITUDE" and m.time_boot_ms == ms)
        hud = next(m for m in reversed(c.log) if m.get_type() == "VFR_HUD")
        s.stop()
    # The same actions in a tssac_core World.
    w = World(scen, n=1)
    w.reset([0], [scen.layout])
    turn_max, accel_max = w.c.turn_rate_max_rad_s[0], w.c.accel_max_m_s2[0]
    action = np.zeros((1, 3, 2))
    action[0, 0] = [-yaw_rate / turn_max, accel / accel_max]
    for _ in range(n1):
        w.step(action)
    action[0, 0] = [-1.0, -1.0]
    for _ in range(n2):
        w.step(action)
    x, y, v, phi = w.x_m[0, 0], w.y_m[0, 0], w.v_m_s[0, 0], w.phi_rad[0, 0]
    assert lpn.x == pytest.approx(y, abs=0.05) and lpn.y == pytest.approx(x, abs=0.05)
    assert lpn.vx == pytest.approx(v * math.sin(phi), abs=1e-3) and lpn.vy == pytest.approx(v * math.cos(phi), abs=1e-3)
    assert att.yaw == pytest.approx(yaw_ned_from_phi(phi), abs=1e-5)
    assert att.yawspeed == pytest.approx(w.c.turn_rate_max_rad_s[0], abs=1e-6)  # clipped right turn
    assert hud.groundspeed == pytest.approx(v, abs=1e-3)
    # The truth log has the exact states, and the other (unarmed) vehicles flew straight.
    steps = [r for r in read_truth_log(truth) if r["type"] == "step"]
    row = steps[n1 + n2 - 1]
    assert row["step"] == n1 + n2
    assert row["vehicles"]["decoy"]["x_m"] == pytest.approx(x, abs=1e-3) and row["vehicles"]["decoy"][
        "y_m"
    ] == pytest.approx(y, abs=1e-3)
    assert row["vehicles"]["detect"]["phi_rad"] == pytest.approx(w.phi_rad[0, 1], abs=1e-6)
    assert row["vehicles"]["decoy"]["mode"] == "GUIDED" and row["vehicles"]["detect"]["armed"] is False


@pytest.mark.timeout(30)
def test_setpoints_refused_unless_armed_in_guided() -> None:
    with sitl(speedup=10.0) as s, Client(s.ports[0]) as c:
        v = s.vehicle(0)
        c.connect()

        def fly_and_watch(seconds: float) -> list:
            msgs = []
            deadline = time.monotonic() + seconds
            while time.monotonic() < deadline:
                c.setpoint(0.05, 5.0)
                msgs += c.collect(0.02)
            return msgs

        def ignored_texts(msgs: list) -> int:
            return sum(1 for m in msgs if m.get_type() == "STATUSTEXT" and "ignored" in m.text)

        # Disarmed: ignored, one STATUSTEXT, no turn.
        msgs = fly_and_watch(0.4)
        assert v.counters.setpoints_ignored >= 5 and v.counters.setpoints_accepted == 0
        assert ignored_texts(msgs) == 1
        atts = [m for m in msgs if m.get_type() == "ATTITUDE"]
        assert atts and all(m.yawspeed == 0.0 for m in atts) and len({round(m.yaw, 9) for m in atts}) == 1
        # Armed in MANUAL: still ignored (one more STATUSTEXT for the new state).
        c.arm()
        msgs = fly_and_watch(0.4)
        assert v.counters.setpoints_accepted == 0 and ignored_texts(msgs) == 1
        assert all(m.yawspeed == 0.0 for m in msgs if m.get_type() == "ATTITUDE")
        # Unsupported frame or mask: rejected whatever the mode.
        c.setpoint(0.05, 5.0, frame=M.MAV_FRAME_LOCAL_NED)
        c.setpoint(0.05, 5.0, mask=0b0000110111111000)
        assert wait_until(lambda: v.counters.setpoints_rejected == 2, 1.0)
        # Armed in GUIDED: obeyed (yaw_rate is clockwise-positive: yawspeed follows it).
        assert c.set_mode(GUIDED).result == M.MAV_RESULT_ACCEPTED
        msgs = fly_and_watch(0.4)
        assert v.counters.setpoints_accepted > 0
        assert any(m.get_type() == "ATTITUDE" and m.yawspeed == pytest.approx(0.05, abs=1e-6) for m in msgs)
        assert v.counters.setpoints_rejected == 2
        s.stop()


@pytest.mark.timeout(30)
def test_setpoint_timeout_failsafe_and_recovery(tmp_path: Path) -> None:
    truth = tmp_path / "truth.jsonl"
    with sitl(speedup=10.0, truth_log=truth) as s, Client(s.ports[1]) as c:
        vehicle = s.vehicle(1)
        c.connect()
        c.arm()
        c.set_mode(GUIDED)
        deadline = time.monotonic() + 0.3
        while time.monotonic() < deadline:
            c.setpoint(0.03, 0.0)
            c.collect(0.02)
        assert c.wait(lambda m: m.get_type() == "STATUSTEXT" and m.text.startswith("Failsafe:"), 3.0) is not None
        last_setpoint_s = vehicle.last_setpoint_s  # no setpoint has been sent since
        hb = c.wait(lambda m: m.get_type() == "HEARTBEAT", 2.0)
        assert hb.system_status == M.MAV_STATE_CRITICAL and vehicle.failsafe
        # Holding heading and speed now.
        now_ms = c.latest_ms
        att = c.wait(lambda m: m.get_type() == "ATTITUDE" and m.time_boot_ms > now_ms, 1.0)
        assert att is not None and att.yawspeed == 0.0
        # Setpoints return: failsafe cleared, ACTIVE again, turning again.
        c.setpoint(0.03, 0.0)
        assert c.wait(lambda m: m.get_type() == "STATUSTEXT" and "cleared" in m.text, 1.0) is not None
        deadline = time.monotonic() + 3.0
        while (hb := c.wait(lambda m: m.get_type() == "HEARTBEAT", 0.1)) is None and time.monotonic() < deadline:
            c.setpoint(0.03, 0.0)
        assert hb is not None and hb.system_status == M.MAV_STATE_ACTIVE
        s.stop()
    # It triggered at the first step more than GUID_TIMEOUT (1.0 s simulated) after the last setpoint.
    failsafe = [r for r in read_truth_log(truth) if r["type"] == "event" and r["event"] == "FAILSAFE"]
    assert [r["value"] for r in failsafe] == [1, 0] and failsafe[0]["vehicle"] == "detect"
    assert 1.0 < failsafe[0]["t_s"] - last_setpoint_s <= 1.1 + 1e-6


# ----------------------------------------------------------------------------------- lockstep


@pytest.mark.timeout(40)
def test_real_time_with_hold_start_waits_for_the_team_then_runs() -> None:
    """--hold-start: a real-time world stands at t = 0 until every vehicle is armed in GUIDED."""
    with sitl(speedup=10.0, hold_start=True) as s:
        clients = [Client(p) for p in s.ports]
        try:
            for c in clients:
                c.connect()
            for c in clients[:2]:
                c.arm()
                c.set_mode(GUIDED)
            time.sleep(0.5)  # 5 simulated seconds at 10x, had the world been running
            assert int(s.runner.world.steps[0]) == 0
            clients[2].arm()
            clients[2].set_mode(GUIDED)
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline and int(s.runner.world.steps[0]) < 20:
                for c in clients:
                    c.setpoint(0.0, 0.0)
                time.sleep(0.05)
            assert int(s.runner.world.steps[0]) >= 20  # 2 simulated seconds: the clock runs
        finally:
            for c in clients:
                c.close()


@pytest.mark.timeout(40)
def test_lockstep_advances_exactly_one_step_per_setpoint_round() -> None:
    from tssac_core.sim.sitl_config import ClockMode

    with sitl(clock=ClockMode.LOCKSTEP, setpoint_timeout_s=1.0) as s:
        clients = [Client(p) for p in s.ports]
        try:
            for c in clients:
                c.connect()
            # Nobody in GUIDED yet: the world holds at t = 0.
            for c in clients[:2]:
                c.arm()
                c.set_mode(GUIDED)
            time.sleep(0.3)
            assert int(s.runner.world.steps[0]) == 0
            clients[2].arm()
            clients[2].set_mode(GUIDED)  # the start gate (all vehicles) opens
            ms = 0
            for k in range(1, 16):
                for c in clients:
                    c.setpoint(0.0, 1.0, stamp_ms=ms)
                for c in clients:
                    tick = c.wait(lambda m: m.get_type() == "SYSTEM_TIME" and m.time_boot_ms > ms, 3.0)
                    assert tick is not None and tick.time_boot_ms == ms + 100, (k, tick)
                ms += 100
                assert int(s.runner.world.steps[0]) == k
            # A partial round does not step the world ...
            for c in clients[:2]:
                c.setpoint(0.0, 1.0, stamp_ms=ms)
            assert clients[0].wait(lambda m: m.get_type() == "SYSTEM_TIME" and m.time_boot_ms > ms, 0.4) is None
            assert int(s.runner.world.steps[0]) == 15
            # ... and a stale stamp (a duplicate of the previous round) does not complete it.
            clients[2].setpoint(0.0, 1.0, stamp_ms=ms - 100)
            assert clients[0].wait(lambda m: m.get_type() == "SYSTEM_TIME" and m.time_boot_ms > ms, 0.3) is None
            clients[2].setpoint(0.0, 1.0, stamp_ms=ms)
            assert (
                clients[0].wait(lambda m: m.get_type() == "SYSTEM_TIME" and m.time_boot_ms == ms + 100, 2.0) is not None
            )
            ms += 100
            # A companion that goes quiet fails safe after the timeout (wall clock) and stops holding the world.
            t0 = time.monotonic()
            for c in clients[:2]:
                c.setpoint(0.0, 1.0, stamp_ms=ms)
            assert (
                clients[2].wait(lambda m: m.get_type() == "STATUSTEXT" and m.text.startswith("Failsafe:"), 3.0)
                is not None
            )
            assert time.monotonic() - t0 >= 0.9
            assert (
                clients[0].wait(lambda m: m.get_type() == "SYSTEM_TIME" and m.time_boot_ms == ms + 100, 2.0) is not None
            )
            assert s.vehicle(2).failsafe and not s.vehicle(2).in_loop
        finally:
            for c in clients:
                c.close()
        s.stop()


# ----------------------------------------------------------------------------------- security


@pytest.mark.timeout(30)
def test_signing_rejects_unsigned_wrong_and_replayed_commands() -> None:
    key = bytes(range(32))
    with sitl(speedup=5.0, signing_key=key) as s:
        v, endpoint = s.vehicle(0), s.endpoint(0)
        rx = endpoint.rx
        with Client(s.ports[0], key=key) as good:
            hb = good.connect()
            assert hb._signed  # the vehicle signs what it sends
            # Unsigned: neither heartbeats nor commands get in (no --unsigned-monitors), and nothing comes back.
            with Client(s.ports[0]) as unsigned:
                unsigned.heartbeat()
                assert unsigned.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, timeout_s=0.3, retries=2) is None
                assert rx.unsigned_rejected >= 3 and not v.armed and unsigned.log == []
            # Wrong key: rejected as a bad signature.
            with Client(s.ports[0], key=bytes(32)) as wrong:
                for _ in range(3):
                    wrong.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
                assert wait_until(lambda: rx.bad_signature >= 3, 1.0)
                assert not v.armed
            # Correctly signed: accepted.
            good.arm()
            assert v.armed
            # A replayed (byte-identical) signed command is refused.
            frame = good.mav.command_long_encode(
                1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0
            ).pack(good.mav)
            good.conn.write(frame)
            assert good.wait_type("COMMAND_ACK", 1.0, command=M.MAV_CMD_REQUEST_MESSAGE) is not None
            good.conn.write(frame)
            assert good.wait_type("COMMAND_ACK", 0.5, command=M.MAV_CMD_REQUEST_MESSAGE) is None
            assert rx.replayed == 1
            # ... and the real sender is not locked out afterwards.
            assert good.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION) is not None
        s.stop()


@pytest.mark.timeout(30)
def test_garbage_on_the_port_is_dropped_and_counted() -> None:
    with sitl(speedup=5.0) as s, Client(s.ports[0]) as c:
        endpoint = s.endpoint(0)
        c.connect()
        valid = c.mav.command_long_encode(
            1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, M.MAVLINK_MSG_ID_HOME_POSITION, 0, 0, 0, 0, 0, 0
        ).pack(c.mav)
        bad_crc = valid[:-1] + bytes([valid[-1] ^ 0xFF])
        rng = random.Random(7)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            for i in range(300):
                if i % 10 == 0:
                    time.sleep(0.003)  # don't overflow the socket's receive buffer: this is about content, not bursts
                sock.sendto(rng.randbytes(rng.randint(1, 400)), ("127.0.0.1", s.ports[0]))
                if i % 20 == 0:
                    sock.sendto(valid[: len(valid) // 2], ("127.0.0.1", s.ports[0]))  # truncated
                    sock.sendto(bad_crc, ("127.0.0.1", s.ports[0]))
                    sock.sendto(b"\xfd\xff\x00" + rng.randbytes(10), ("127.0.0.1", s.ports[0]))  # lying length
            sock.sendto(rng.randbytes(60_000), ("127.0.0.1", s.ports[0]))
            assert wait_until(lambda: endpoint.rx.datagrams >= 300 + 15 * 3 + 1, 3.0)
        finally:
            sock.close()
        rx = endpoint.rx
        assert rx.garbage_bytes > 10_000 and rx.truncated >= 15 and rx.bad_crc >= 15
        assert len(endpoint.peers) == 1  # the garbage sender never became a peer
        # Still serving: telemetry flows and commands are answered; a valid frame behind garbage is found.
        assert c.wait_type("HEARTBEAT", 2.0) is not None
        c.conn.write(b"\x00\x01garbage" + valid)
        assert c.wait_type("COMMAND_ACK", 1.0, command=M.MAV_CMD_REQUEST_MESSAGE) is not None
        assert s.thread.is_alive()
        s.stop()


@pytest.mark.timeout(30)
def test_hostile_field_values_never_break_the_vehicle() -> None:
    """Well-formed messages with absurd values (NaN, inf, huge, negative) are refused, not crashed on."""
    rng = random.Random(11)
    floats = [math.nan, math.inf, -math.inf, 1e30, -1e30, -1.0, 0.0, 1.0, 15.0, 21196.0, 2.5e9]

    def f() -> float:
        return rng.choice(floats) if rng.random() < 0.7 else rng.uniform(-1e6, 1e6)

    commands = [400, 176, 510, 511, 512, 520, 0, 65535]
    with sitl(speedup=5.0) as s, Client(s.ports[0]) as c:
        v = s.vehicle(0)
        c.connect()
        c.arm()
        c.set_mode(GUIDED)
        for i in range(400):
            kind = i % 6
            if kind == 0:
                c.mav.command_long_send(1, 1, rng.choice(commands), rng.randint(0, 255), *(f() for _ in range(7)))
            elif kind == 1:
                c.mav.command_int_send(
                    1,
                    1,
                    rng.randint(0, 21),
                    rng.choice(commands),
                    0,
                    0,
                    f(),
                    f(),
                    f(),
                    f(),
                    rng.randint(-(2**31), 2**31 - 1),
                    rng.randint(-(2**31), 2**31 - 1),
                    f(),
                )
            elif kind == 2:
                c.mav.set_mode_send(1, rng.randint(0, 255), rng.randint(0, 2**32 - 1))
            elif kind == 3:
                c.mav.param_set_send(
                    1, 1, rng.choice([b"GUID_TIMEOUT", b"SYSID_THISMAV", b"NOPE", b"\xff\xfe"]), f(), rng.randint(0, 10)
                )
            elif kind == 4:
                c.mav.param_request_read_send(1, 1, b"SIM_DT", rng.randint(-32768, 32767))
            else:
                c.setpoint(
                    f(), f(), stamp_ms=rng.randint(0, 2**32 - 1), mask=rng.randint(0, 65535), frame=rng.randint(0, 255)
                )
            if i % 20 == 0:
                c.collect(0.005)
        c.collect(0.3)
        assert v.counters.handler_errors == 0
        assert s.thread.is_alive() and c.wait_type("HEARTBEAT", 2.0) is not None
        ack = c.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        s.stop()


# ---------------------------------------------------------------------------------- link model


@pytest.mark.timeout(30)
def test_configured_packet_loss_is_observed() -> None:
    loss = 0.3
    with sitl(scenario(LinkModel(packet_loss=loss)), speedup=20.0, seed=3) as s, Client(s.ports[0]) as c:
        c.connect()
        msgs = c.collect(1.5)  # ~30 s of simulated time: ~300 ATTITUDE sent
        att = sorted(m.time_boot_ms for m in msgs if m.get_type() == "ATTITUDE")
        sent = (att[-1] - att[0]) / 100 + 1
        assert len(att) / sent == pytest.approx(1 - loss, abs=0.08)
        # Incoming: the vehicle's incoming channel drops datagrams at the same rate.
        link_in = s.link(0).rx.counters
        before_pushed, before_lost = link_in.pushed, link_in.lost
        for _ in range(400):
            c.heartbeat()
        assert wait_until(lambda: link_in.pushed - before_pushed >= 400, 2.0)
        assert (link_in.lost - before_lost) / (link_in.pushed - before_pushed) == pytest.approx(loss, abs=0.08)
        s.stop()


# ----------------------------------------------------------------------- mission, truth log, CLI


def _quick_mission() -> object:
    """A fixed layout where the radar comes on and the target is identified at once, detect enters a
    radar after a few steps and the strike UAV reaches R1 after about 12 steps (mission success)."""
    base = scenario()
    layout = Layout(
        sam_km=(65.0, 65.0),
        target_km=(66.0, 65.0),
        radars=(Radar((67.2, 53.5), 2.0),),
        starts={
            "decoy": Start((46.5, 65.0), 90.0),  # 18.5 km west of the SAM, flying north: in its ring
            "detect": Start((65.0, 53.5), 0.0),  # 11.5 km south, flying east into the radar
            "strike": Start((75.3, 65.0), 180.0),  # 10.3 km east, flying at the SAM
        },
    )
    return dataclasses.replace(base, layout=layout)


@pytest.mark.timeout(30)
def test_mission_events_truth_log_and_tlog(tmp_path: Path) -> None:
    scen = _quick_mission()
    truth, tlogs = tmp_path / "truth.jsonl", tmp_path / "tlogs"
    with sitl(scen, truth_log=truth, tlog_dir=tlogs, linger_s=0.5, **lockstep()) as s, Client(s.ports[1]) as c:
        c.connect()
        c.arm()
        c.set_mode(GUIDED)
        ended = None
        for _ in range(40):
            _lockstep_round(c, 0.0, 0.0)
            ended = next((m for m in c.log if m.get_type() == "NAMED_VALUE_INT" and m.name == "MSN_END"), None)
            if ended is not None:
                break
        assert ended is not None and ended.value == 1
        c.collect(0.3)
        texts = [m.text for m in c.log if m.get_type() == "STATUSTEXT"]
        for expected in (
            "SAM radar ON",
            "Target identified",
            "Hazard: detect entered radar range",
            "Target hit",
            "Mission end: success",
        ):
            assert expected in texts
        named = {(m.name, m.value) for m in c.log if m.get_type() == "NAMED_VALUE_INT"}
        assert {("RADAR_ON", 1), ("IDENT", 1), ("HAZARD", 1), ("HIT", 1), ("MSN_END", 1)} <= named
        assert wait_until(lambda: not s.thread.is_alive(), 5.0), "the run did not end after the mission"
        result = s.runner.result
    assert result.end == "success" and result.success and result.cost["detect"] > 0
    records = read_truth_log(truth)
    assert records[0]["type"] == "header" and records[0]["layout"]["sam_km"] == [65.0, 65.0]
    steps = [r for r in records if r["type"] == "step"]
    assert [r["step"] for r in steps] == list(range(1, result.steps + 1))
    events = [(r["event"], r["value"]) for r in records if r["type"] == "event"]
    assert ("RADAR_ON", 1) in events and ("HIT", 1) in events and ("ARMED", 1) in events and ("MODE", GUIDED) in events
    summary = records[-1]
    assert summary["type"] == "summary" and summary["success"] is True and summary["end"] == "success"
    assert summary["cost"]["detect"] == sum(r["vehicles"]["detect"]["cost"] for r in steps)
    # The tlog is readable by pymavlink (what mavlogdump.py uses) and holds both directions.
    log = mavutil.mavlink_connection(str(tlogs / "detect.tlog"))
    types = set()
    while (m := log.recv_msg()) is not None:
        types.add(m.get_type())
    assert {"HEARTBEAT", "ATTITUDE", "COMMAND_LONG", "COMMAND_ACK", "SET_POSITION_TARGET_LOCAL_NED"} <= types


@pytest.mark.timeout(30)
def _fly_to_the_mission_end(c: Client) -> None:
    """Engage the client's vehicle and answer lockstep rounds until the world announces the mission's end."""
    c.connect()
    c.arm()
    c.set_mode(GUIDED)
    for _ in range(40):
        _lockstep_round(c, 0.0, 0.0)
        if any(m.get_type() == "NAMED_VALUE_INT" and m.name == "MSN_END" for m in c.log):
            return


def test_a_lockstep_linger_serves_its_simulated_seconds_without_waiting_for_them() -> None:
    """Under lockstep the linger's steps run back to back on the link's simulated clock: the whole linger reaches the
    client (its ticks, and a POWEROFF heartbeat each simulated second) and the run ends long before the linger's wall
    time (paced, as in real-time mode, it would take it all). Twenty seconds keep the burst well inside the client's
    socket buffer on a loaded machine, where the test thread reads slowly beside the world's."""
    linger_s = 20.0
    with sitl(_quick_mission(), linger_s=linger_s, **lockstep()) as s, Client(s.ports[1]) as c:
        _fly_to_the_mission_end(c)
        end_ms = c.latest_ms
        deadline = time.monotonic() + linger_s / 4
        while s.thread.is_alive() and time.monotonic() < deadline:
            c.collect(0.05)  # read as it comes: a loaded machine's socket buffer would drop a minute of ticks
        assert not s.thread.is_alive(), "the linger waited for wall time"
        c.drain()
    ticks = [m.time_boot_ms for m in c.log if m.get_type() == "SYSTEM_TIME"]
    assert max(ticks) >= end_ms + linger_s * 1000 - 100  # its last tick, one step short of the linger's end at most
    poweroff = [m for m in c.log if m.get_type() == "HEARTBEAT" and m.system_status == mavlink2.MAV_STATE_POWEROFF]
    assert len(poweroff) >= linger_s - 1


def test_a_lockstep_world_lingers_straight_after_its_last_step(monkeypatch: pytest.MonkeyPatch) -> None:
    """Once the mission has ended under lockstep the world does not wait on its sockets before the linger (it used
    to wait its 50 ms select timeout: about a twentieth of a kept crew's mission)."""
    waits: list[tuple[str, float]] = []
    real_wait_s = WorldRunner._wait_s

    def watched_wait_s(self: WorldRunner, now_wall: float, deadline_wall: float | None) -> float:
        wait = real_wait_s(self, now_wall, deadline_wall)
        waits.append((self.clock_policy.phase.value, wait))
        return wait

    monkeypatch.setattr(WorldRunner, "_wait_s", watched_wait_s)
    with sitl(_quick_mission(), linger_s=1.0, **lockstep()) as running, Client(running.ports[1]) as c:
        _fly_to_the_mission_end(c)
        assert wait_until(lambda: not running.thread.is_alive(), 5.0)
    after_end = [timeout for phase, timeout in waits if phase in ("linger", "done")]
    assert after_end == [0.0] * len(after_end)
    assert any(phase == "run" and timeout > 0 for phase, timeout in waits)  # it did wait for the client while flying


def test_random_scenario_layout_is_seeded_and_written(tmp_path: Path) -> None:
    scen = load(REPO / "scenarios" / "random.yaml")
    out = tmp_path / "layout.yaml"
    runner = WorldRunner(SitlConfig(scenario=scen, seed=5, base_port=0, layout_out=out))
    try:
        fixed = load(out)
        assert fixed.random is None and fixed.layout == sample_layout(scen, np.random.default_rng(5)) == runner.layout
        assert runner.world.x_m[0, 0] == pytest.approx(fixed.layout.starts["decoy"].position_km[0] * 1000)
    finally:
        runner.close()


def _run_cli(args: list[str], timeout_s: float = 30.0) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run(
        [sys.executable, "-m", "sim_vehicles", *args],
        capture_output=True,
        text=True,
        timeout=timeout_s,
        cwd=REPO,
        env=env,
    )


@pytest.mark.timeout(60)
def test_cli_bad_input_exits_2_with_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed\n")
    proc = _run_cli(["--scenario", str(bad), "--base-port", "0"])
    assert proc.returncode == 2 and proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "bad.yaml" in lines[0] and "YAML" in lines[0], proc.stderr
    # In-process: missing file, bad key file, bad option, port in use.
    key = tmp_path / "k"
    key.write_text("short")
    blocker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    blocker.bind(("127.0.0.1", 0))
    try:
        for argv, needle in [
            (["--scenario", str(tmp_path / "nope.yaml")], "cannot read"),
            (["--scenario", str(STRIKE), "--signing-key", str(key)], "32 raw bytes"),
            (["--scenario", str(STRIKE), "--lockstep", "--speedup", "2"], "not allowed"),
            (["--scenario", str(STRIKE), "--speedup", "-1", "--base-port", "0"], "speedup"),
            (["--scenario", str(STRIKE), "--base-port", str(blocker.getsockname()[1])], "in use"),
        ]:
            assert _main_exit_code(argv) == 2
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and needle in err[0], (argv, err)
    finally:
        blocker.close()


def _main_exit_code(argv: list[str]) -> int:
    """main(argv)'s exit status, whether it returns it or argparse raises SystemExit."""
    try:
        return main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)


@pytest.mark.timeout(60)
def test_cli_sigterm_stops_cleanly(tmp_path: Path) -> None:
    truth = tmp_path / "truth.jsonl"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    cmd = [
        sys.executable,
        "-m",
        "sim_vehicles",
        "--scenario",
        str(STRIKE),
        "--base-port",
        "0",
        "--speedup",
        "5",
        "--truth-log",
        str(truth),
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO, env=env)
    try:
        assert proc.stdout is not None
        buf = b""
        deadline = time.monotonic() + 20.0
        while b"\nready" not in b"\n" + buf:
            assert time.monotonic() < deadline and proc.poll() is None, (buf, proc.poll())
            if select.select([proc.stdout], [], [], 0.5)[0]:
                buf += os.read(proc.stdout.fileno(), 4096)
        lines = buf.decode().splitlines()
        assert [ln.split()[:2] for ln in lines[:3]] == [
            ["decoy", "sysid=1"],
            ["detect", "sysid=2"],
            ["strike", "sysid=3"],
        ]
        port = int(lines[0].rsplit(":", 1)[1])
        assert lines[0].split()[2] == f"udpout:127.0.0.1:{port}"
        with Client(port) as c:
            c.connect()
            assert c.wait(lambda m: m.get_type() == "ATTITUDE" and m.time_boot_ms >= 500, 5.0) is not None
        proc.send_signal(signal.SIGTERM)
        out_b, err_b = proc.communicate(timeout=15)
        out, err = buf.decode() + out_b.decode(), err_b.decode()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
    assert proc.returncode == 0, err
    assert "end reason=stopped" in out
    summary = read_truth_log(truth)[-1]
    assert summary["type"] == "summary" and summary["end"] == "stopped" and summary["steps"] > 0
    # The socket was closed: the port can be bound again.
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        probe.bind(("127.0.0.1", port))
    finally:
        probe.close()


def test_truth_log_step_lines_are_the_bytes_json_dumps_writes() -> None:
    from tssac_core.wire.truth_log_schema import STEP, VEHICLES_KEY, AirRow, VehicleRow, encode, encode_step

    rng = np.random.default_rng(11)
    odd = [0.0, -0.0, 1e-9, 123456789.123456789, math.nan, math.inf, -math.inf, 5e-324, 1e300]

    def number() -> float:
        return float(rng.choice(odd)) if rng.random() < 0.2 else float(rng.normal(0.0, 10.0 ** rng.integers(-8, 8)))

    for step in range(300):
        rows = [
            VehicleRow(
                role=role,
                x_m=number(),
                y_m=number(),
                v_m_s=number(),
                phi_rad=number(),
                cost=float(rng.integers(0, 2)),
                cost_total=number(),
                omega_cmd=number(),
                u_cmd=number(),
                armed=bool(rng.integers(0, 2)),
                mode=str(rng.choice(["MANUAL", "GUIDED", "RTL"])),
                failsafe=bool(rng.integers(0, 2)),
                turn_rate_rad_s=number(),
                accel_m_s2=number(),
                air=AirRow(number(), number(), number(), number(), number()) if rng.random() < 0.5 else None,
            )
            for role in ("decoy", "detect", "strike")
        ]
        flags = {"radar_on": bool(rng.integers(0, 2)), "identified": bool(rng.integers(0, 2)), "hit": False}
        t_s = step * 0.1 if step % 7 else number()
        record = {"type": STEP, "step": step, "t_s": round(t_s, 6), **flags}
        record[VEHICLES_KEY] = {r.role: r.as_dict() for r in rows}
        assert encode_step(step, t_s, flags, rows) == encode(record)
