"""The companion and its MAVLink link, over real UDP on 127.0.0.1 (OS-assigned ports) against real SITL vehicles.

The SITL world runs in a thread (tests/sitl_helpers.py) or as a subprocess; the companion runs as
its command line (a subprocess). Where a test must see or disturb the traffic between the two it puts
a UDP relay in between: real sockets that forward datagrams both ways, record what they carry
(decoded with pymavlink) and, on request, drop the vehicle-to-companion direction or switch to
another vehicle. Every wait is bounded on time.monotonic() and every test has a timeout.
"""

from __future__ import annotations

import json
import math
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sitl_helpers import EXACT_LINK, REPO, STRIKE, lockstep, mavlink2, mavutil, scenario, sitl, wait_until

from mavlink_bridge.companion import cli as companion_cli
from mavlink_bridge.link.connection import (
    SETPOINT_FRAME,
    SETPOINT_TYPE_MASK,
    CommandError,
    LinkError,
    MavLink,
    parse_connection,
)
from mavlink_bridge.link.frames import action_to_setpoint, from_global_position_int, from_local_position_ned
from tssac_core.sim.scenario import LinkModel, Role, dump, load
from tssac_core.sim.world import World
from tssac_core.sim.world_state import snapshot
from tssac_core.wire.geodetic import local_to_geodetic
from tssac_core.wire.lockstep import GRANT_NAME
from tssac_core.wire.signing import now_10us
from tssac_core.wire.truth_log_schema import read_truth_log
from tssac_core.wire.units import deg_e7

# One test process runs this file: its module fixture is built once.
pytestmark = pytest.mark.xdist_group("test_bridge")

M = mavlink2
GUIDED = 15


# ------------------------------------------------------------------------------------ helpers


class UdpRelay:
    """A UDP relay between a companion and a vehicle: two real sockets and a forwarding thread.

    The companion talks to ``relay.port``; the relay forwards to ``upstream`` and back. It records
    every message it forwards, decoded, with the wall time (``to_vehicle``, ``to_companion``), and
    drops the vehicle-to-companion direction while ``drop_to_companion`` is set.
    """

    def __init__(self, upstream_port: int) -> None:
        self.down = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.down.bind(("127.0.0.1", 0))
        self.up = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.up.bind(("127.0.0.1", 0))
        self.port = self.down.getsockname()[1]
        self.upstream = ("127.0.0.1", upstream_port)
        self.companion: tuple[str, int] | None = None
        self.drop_to_companion = threading.Event()
        self.dropped = 0
        self.to_vehicle: list[tuple[float, Any]] = []
        self.to_companion: list[tuple[float, Any]] = []
        self._parsers = {"up": mavlink2.MAVLink(None), "down": mavlink2.MAVLink(None)}
        for p in self._parsers.values():
            p.robust_parsing = True
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, name="relay", daemon=True)
        self._thread.start()

    def _decode(self, direction: str, data: bytes) -> list[Any]:
        parser = self._parsers[direction]
        msgs = [m for m in (parser.parse_buffer(data) or []) if m.get_type() != "BAD_DATA"]
        parser.buf, parser.buf_index, parser.expected_length = bytearray(), 0, mavlink2.HEADER_LEN_V1 + 2
        return msgs

    def _run(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self.down, self.up], [], [], 0.05)
            for sock in ready:
                try:
                    data, addr = sock.recvfrom(65535)
                except OSError:
                    continue
                now = time.monotonic()
                if sock is self.down:
                    self.companion = addr
                    with self._lock:
                        self.to_vehicle += [(now, m) for m in self._decode("up", data)]
                        target = self.upstream
                    self.up.sendto(data, target)
                elif self.companion is not None:
                    if self.drop_to_companion.is_set():
                        self.dropped += 1
                        continue
                    with self._lock:
                        self.to_companion += [(now, m) for m in self._decode("down", data)]
                    self.down.sendto(data, self.companion)

    def switch_upstream(self, port: int) -> None:
        with self._lock:
            self.upstream = ("127.0.0.1", port)

    def sent(self, mtype: str) -> list[tuple[float, Any]]:
        with self._lock:
            return [(t, m) for t, m in self.to_vehicle if m.get_type() == mtype]

    def received(self, mtype: str) -> list[tuple[float, Any]]:
        with self._lock:
            return [(t, m) for t, m in self.to_companion if m.get_type() == mtype]

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.down.close()
        self.up.close()

    def __enter__(self) -> UdpRelay:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _env() -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(REPO))


class CompanionProcess:
    """``python -m mavlink_bridge.companion`` as a subprocess; always stopped (SIGTERM, then SIGKILL)."""

    def __init__(self, tmp: Path, port: int, scenario_file: Path, *args: str, role: str = "decoy") -> None:
        self.status_path = tmp / f"{role}.status.json"
        self.log_path = tmp / f"{role}.log"
        self.tlog_path = tmp / f"{role}.tlog"
        argv = [
            sys.executable,
            "-m",
            "mavlink_bridge.companion",
            "--connect",
            f"udpout:127.0.0.1:{port}",
            "--role",
            role,
            "--scenario",
            str(scenario_file),
            "--status-json",
            str(self.status_path),
            "--tlog",
            str(self.tlog_path),
            *args,
        ]
        if "--model" not in args:
            argv += ["--pilot", "guidance"]
        self._log = open(self.log_path, "wb")
        self.proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=self._log, cwd=REPO, env=_env())

    def wait(self, timeout_s: float) -> tuple[int, str]:
        out, _ = self.proc.communicate(timeout=timeout_s)
        return self.proc.returncode, out.decode()

    def status(self) -> dict[str, Any]:
        return json.loads(self.status_path.read_text())

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        self._log.close()

    def __enter__(self) -> CompanionProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _scenario_file(tmp: Path, link: LinkModel = EXACT_LINK) -> Path:
    path = tmp / "scenario.yaml"
    dump(scenario(link), path)
    return path


def _until(predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
    assert wait_until(predicate, timeout_s, 0.02), f"timed out waiting for {what}"


# ------------------------------------------------------------------------------ pure parts


def test_frames_follow_the_sitl_conventions() -> None:
    spec = scenario().vehicle(Role.DECOY)
    turn = math.radians(spec.turn_rate_max_deg_s)
    # omega is CCW-positive, yaw_rate clockwise-positive: a left turn is a negative yaw rate.
    sp = action_to_setpoint((1.0, -0.5), spec)
    assert sp.yaw_rate_rad_s == pytest.approx(-turn) and sp.accel_m_s2 == pytest.approx(-0.5 * spec.accel_max_m_s2)
    assert action_to_setpoint((7.0, 3.0), spec).yaw_rate_rad_s == pytest.approx(-turn)  # clipped
    m = from_local_position_ned(1500, x_m=2000.0, y_m=1000.0, vx_m_s=3.0, vy_m_s=4.0)
    assert (m.t_s, m.east_m, m.north_m, m.vel_east_m_s, m.vel_north_m_s) == (1.5, 1000.0, 2000.0, 4.0, 3.0)
    origin = scenario().origin
    for east, north in [(0.0, 0.0), (12_345.6, 98_765.4), (100_000.0, 50_000.0)]:
        lat, lon = local_to_geodetic(origin, east, north)  # the SITL's projection
        g = from_global_position_int(origin, 0, deg_e7(lat), deg_e7(lon), 0, 0)
        assert g.east_m == pytest.approx(east, abs=0.02) and g.north_m == pytest.approx(north, abs=0.02)
    assert SETPOINT_FRAME == M.MAV_FRAME_BODY_FRD and SETPOINT_TYPE_MASK & ~(128 | 256) == 1087
    assert parse_connection("udp:0.0.0.0:14550").kind == "udpin"
    for bad in ("tcp:127.0.0.1:5760", "udpout:127.0.0.1", "udpout:127.0.0.1:x", "udpout:127.0.0.1:0"):
        with pytest.raises(ValueError):
            parse_connection(bad)


# ------------------------------------------------------------------------------------ link


@pytest.mark.timeout(60)
def test_link_commands_are_acknowledged_retried_and_nothing_is_lost() -> None:
    with sitl(speedup=5.0) as s:
        with MavLink(f"udpout:127.0.0.1:{s.ports[0]}") as link:
            hb = link.wait_heartbeat(5.0)
            assert link.target_system == 1 and hb.type == M.MAV_TYPE_FIXED_WING
            time.sleep(0.3)  # telemetry piles up in the socket while we are busy
            ack = link.arm()
            ack_rx_s = link.last_rx_s
            assert ack.result == M.MAV_RESULT_ACCEPTED and s.vehicle(0).armed
            # What arrived before the ACK is still delivered afterwards, in order.
            first = link.recv(0.0)
            assert first is not None and first.get_type() != "COMMAND_ACK" and link.last_rx_s <= ack_rx_s
            with pytest.raises(CommandError) as refused:
                link.set_mode(5)  # not a mode the vehicle has
            assert refused.value.result == M.MAV_RESULT_DENIED
            link.set_mode(GUIDED)
            assert wait_until(lambda: s.vehicle(0).mode == GUIDED, 1.0)
            link.set_message_interval(M.MAVLINK_MSG_ID_ATTITUDE, -1)
            assert s.link(0).streams.streams[M.MAVLINK_MSG_ID_ATTITUDE].interval_s is None
        s.stop()
    # A peer that never answers: every attempt times out, retries are counted, the wait is bounded.
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    try:
        with MavLink(f"udpout:127.0.0.1:{silent.getsockname()[1]}", target_system=1) as link:
            t0 = time.monotonic()
            with pytest.raises(CommandError, match="no COMMAND_ACK"):
                link.command_long(M.MAV_CMD_COMPONENT_ARM_DISARM, (1.0,), timeout_s=0.2, retries=3)
            assert 0.55 <= time.monotonic() - t0 < 2.0
            assert link.counters.command_retries == 2 and link.counters.messages_tx == 3
            with pytest.raises(LinkError, match="no heartbeat"):
                link.wait_heartbeat(0.3)
    finally:
        silent.close()


@pytest.mark.timeout(60)
def test_link_signing_right_key_flies_wrong_or_no_key_is_refused() -> None:
    key = bytes(range(32))
    with sitl(speedup=5.0, signing_key=key) as s:
        with MavLink(f"udpout:127.0.0.1:{s.ports[0]}", signing_key=key) as link:
            link.wait_heartbeat(5.0)
            assert link.arm().result == M.MAV_RESULT_ACCEPTED
            assert link.counters.signature_rejected == 0
        with MavLink(f"udpout:127.0.0.1:{s.ports[1]}", signing_key=bytes(32), target_system=2) as wrong:
            with pytest.raises(LinkError, match="no heartbeat"):
                wrong.wait_heartbeat(1.0)  # a wrongly signed HEARTBEAT buys nothing: not a byte comes back ...
            assert wrong.counters.datagrams_rx == 0
            with pytest.raises(CommandError, match="no COMMAND_ACK"):
                wrong.arm(timeout_s=0.3, retries=2)  # ... and it obeys nothing we sign
        assert s.endpoint(1).rx.bad_signature >= 2 and not s.vehicle(1).armed
        with MavLink(f"udpout:127.0.0.1:{s.ports[2]}") as unsigned:
            with pytest.raises(LinkError, match="no heartbeat"):
                unsigned.wait_heartbeat(1.0)  # unsigned HEARTBEATs pass only with --unsigned-monitors ...
            with pytest.raises(CommandError, match="no COMMAND_ACK"):
                unsigned.arm(timeout_s=0.3, retries=2)  # ... and no unsigned command is obeyed
            assert unsigned.counters.datagrams_rx == 0
        assert not s.vehicle(2).armed and s.endpoint(2).rx.unsigned_rejected >= 2
        s.stop()


def _hostile_datagrams(vehicle: mavlink2.MAVLink) -> list[bytes]:
    """Real frames from system 1 behind garbage: an unknown-id header covering the next frame, a bad-CRC frame,
    a well-formed frame of an unknown message id, and a frame cut off at the end of its datagram."""
    hb = bytes(vehicle.heartbeat_encode(M.MAV_TYPE_FIXED_WING, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0).pack(vehicle))
    st = bytes(vehicle.system_time_encode(1_700_000_000_000_000, 1234).pack(vehicle))
    unknown_header = bytes([0xFD, len(hb) - 2, 0, 0, 0, 1, 1, 0xEE, 0xEE, 0xEE])
    bad_crc = st[:-2] + bytes([st[-2] ^ 0xFF, st[-1]])
    body = bytes([0xFD, 4, 0, 0, 7, 1, 1, 0x39, 0x30, 0x00, 1, 2, 3, 4])  # message id 12345: not in the dialect
    unknown_frame = body + bytes(2)
    return [
        unknown_header + hb,
        bad_crc + b"\x00junk" + st,
        unknown_frame + hb,
        hb[:-5],  # cut off: dropped, and it must not swallow the next datagram
        st,
    ]


@pytest.mark.timeout(30)
def test_link_finds_a_frame_behind_garbage_and_drops_unknown_ids_as_the_sitl_does() -> None:
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    packer = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    datagrams = _hostile_datagrams(packer)
    expected = ["HEARTBEAT", "SYSTEM_TIME", "HEARTBEAT", "SYSTEM_TIME"]
    try:
        with MavLink(f"udpout:127.0.0.1:{vehicle.getsockname()[1]}", target_system=1) as link:
            link.send_heartbeat()
            _, companion = vehicle.recvfrom(4096)
            for datagram in datagrams:
                vehicle.sendto(datagram, companion)
            got = []
            deadline = time.monotonic() + 5.0
            while len(got) < len(expected) and time.monotonic() < deadline:
                msg = link.recv(0.2)
                if msg is not None:
                    got.append(msg.get_type())
            assert link.recv(0.3) is None  # nothing else, no UNKNOWN_* message
            assert got == expected
            assert link.counters.truncated_rx == 1 and link.counters.bad_data_rx >= 3
    finally:
        vehicle.close()
    # The SITL's endpoint splits the same bytes into the same messages.
    from sim_vehicles.link.mavlink_io import MavEndpoint

    endpoint = MavEndpoint("127.0.0.1", 0, 2, 1)
    try:
        sitl_got = [m.get_type() for d in datagrams for m in endpoint.parse(d, ("127.0.0.1", 9)).messages]
    finally:
        endpoint.close()
    assert sitl_got == expected


# ------------------------------------------------------------------------------- companion


@pytest.mark.timeout(120)
def test_companion_arms_guides_and_the_vehicle_flies_its_setpoints(tmp_path: Path) -> None:
    scen_file = _scenario_file(tmp_path)
    truth = tmp_path / "truth.jsonl"
    duration_s = 15.0
    # A long setpoint timeout (wall seconds at the lockstep barrier): a loaded test machine must not trip it.
    with (
        sitl(load(scen_file), truth_log=truth, setpoint_timeout_s=5.0, **lockstep()) as s,
        UdpRelay(s.ports[0]) as relay,
    ):
        with CompanionProcess(tmp_path, relay.port, scen_file, "--lockstep", "--duration-s", str(duration_s)) as comp:
            code, out = comp.wait(90)
            assert code == 0, comp.log()
            assert "status=duration" in out
            status = comp.status()
        s.stop()
    # Every command was acknowledged as accepted.
    acks = {m.command: m.result for _, m in relay.received("COMMAND_ACK")}
    assert (
        acks[M.MAV_CMD_COMPONENT_ARM_DISARM] == M.MAV_RESULT_ACCEPTED
        and acks[M.MAV_CMD_DO_SET_MODE] == M.MAV_RESULT_ACCEPTED
    )
    setpoints = {m.time_boot_ms: m for _, m in relay.sent("SET_POSITION_TARGET_LOCAL_NED")}
    n = int(duration_s * 10)
    assert sorted(setpoints) == [100 * k for k in range(n + 1)]  # one per tick, stamped with the tick
    assert all(m.coordinate_frame == SETPOINT_FRAME and m.type_mask == SETPOINT_TYPE_MASK for m in setpoints.values())
    assert status["counters"]["holds"] == 0 and status["latency_ms"]["n"] == n + 1
    # The vehicle flew exactly what was sent: step k flies the setpoint stamped at tick k - 1.
    scen = load(scen_file)
    world = World(scen, 1)
    world.reset([0], [scen.layout])
    turn, accel = world.c.turn_rate_max_rad_s[0], world.c.accel_max_m_s2[0]
    rows = [r for r in read_truth_log(truth) if r["type"] == "step"]
    assert len(rows) >= n
    action = np.zeros((1, 3, 2))
    turned = 0
    for row in rows[:n]:
        sp = setpoints[(row["step"] - 1) * 100]
        decoy = row["vehicles"]["decoy"]
        assert decoy["armed"] and decoy["mode"] == "GUIDED" and not decoy["failsafe"]
        assert decoy["omega_cmd"] == pytest.approx(-sp.yaw_rate / turn, abs=1e-6)
        assert decoy["u_cmd"] == pytest.approx(sp.afx / accel, abs=1e-6)
        turned += abs(sp.yaw_rate) > 1e-3
        action[0, 0] = [-sp.yaw_rate / turn, sp.afx / accel]
        world.step(action)
        assert (decoy["x_m"], decoy["y_m"]) == pytest.approx((world.x_m[0, 0], world.y_m[0, 0]), abs=0.01)
    assert turned > 10  # the guidance turned the vehicle: these were not hold commands
    start = scen.layout.starts["decoy"].position_km
    assert math.dist(start, (world.x_m[0, 0] / 1000, world.y_m[0, 0] / 1000)) > 3.0


@pytest.mark.timeout(120)
def test_companion_holds_through_a_telemetry_gap_and_resumes(tmp_path: Path) -> None:
    scen_file = _scenario_file(tmp_path, LinkModel(gps_position_sigma_m=5.0, gps_velocity_sigma_m_s=0.5))
    truth = tmp_path / "truth.jsonl"
    speedup, gap_s = 5.0, 2.0
    # Setpoint timeout 2 s of vehicle time (0.4 s of wall), well inside the gap's 10 s of vehicle time: only
    # the companion's hold setpoints can keep the vehicle out of its failsafe through the gap.
    with (
        sitl(load(scen_file), truth_log=truth, speedup=speedup, setpoint_timeout_s=2.0) as s,
        UdpRelay(s.ports[0]) as relay,
    ):
        with CompanionProcess(tmp_path, relay.port, scen_file, "--hold-after-s", "0.5") as comp:
            # Long enough for the companion to have measured the vehicle's clock rate (0.5 s windows).
            _until(lambda: len(relay.sent("SET_POSITION_TARGET_LOCAL_NED")) >= 60, 30.0, "the companion to fly")
            relay.drop_to_companion.set()
            gap_start = time.monotonic()
            time.sleep(gap_s)
            relay.drop_to_companion.clear()
            gap_end = time.monotonic()
            _until(
                lambda: any(t > gap_end for t, m in relay.sent("STATUSTEXT") if "resuming" in m.text),
                10.0,
                "the companion to resume",
            )
            time.sleep(0.5)
            stopped_ms = s.vehicle(0).clock.time_boot_ms  # after this the vehicle is on its own: its failsafe may fire
            comp.proc.send_signal(signal.SIGTERM)
            code, out = comp.wait(15)
            assert code == 0 and "status=stopped" in out, comp.log()
            status = comp.status()
            log = comp.log()
        vehicle = s.vehicle(0)
        assert vehicle.armed and vehicle.mode == GUIDED
        s.stop()
    assert relay.dropped > 20
    setpoints = relay.sent("SET_POSITION_TARGET_LOCAL_NED")
    # Hold after 0.5 s of vehicle time (0.1 s of wall at 5x; 0.5 s of margin) until the gap ends.
    in_gap = [m for t, m in setpoints if gap_start + 0.5 < t < gap_end]
    assert len(in_gap) >= 10 and all(m.yaw_rate == 0.0 and m.afx == 0.0 for m in in_gap)
    after = [m for t, m in setpoints if t > gap_end + 0.3]
    assert after and any(m.yaw_rate != 0.0 or m.afx != 0.0 for m in after)
    texts = [(t, m.text) for t, m in relay.sent("STATUSTEXT")]
    assert any(gap_start < t < gap_end and "telemetry gap" in text and "holding" in text for t, text in texts), texts
    assert "sending the hold setpoint" in log
    assert status["counters"]["hold_episodes"] >= 1 and status["counters"]["extrapolated_steps"] > 5
    # The companion kept the vehicle under control: its own setpoint failsafe never fired while the companion
    # ran. (After SIGTERM it may: the world flies on at 5x until s.stop(), seconds later on a loaded machine.)
    rows = [r for r in read_truth_log(truth) if r["type"] == "step" and r["step"] * 100 < stopped_ms]
    assert len(rows) > 100 and not any(r["vehicles"]["decoy"]["failsafe"] for r in rows)
    # The tlog is readable (what mavlogdump.py uses) and has both directions.
    tlog = mavutil.mavlink_connection(str(tmp_path / "decoy.tlog"))
    types = set()
    while (m := tlog.recv_msg()) is not None:
        types.add(m.get_type())
    assert {
        "HEARTBEAT",
        "LOCAL_POSITION_NED",
        "COMMAND_LONG",
        "COMMAND_ACK",
        "SET_POSITION_TARGET_LOCAL_NED",
        "STATUSTEXT",
    } <= types


@pytest.mark.timeout(120)
def test_companion_reengages_a_restarted_vehicle(tmp_path: Path) -> None:
    scen_file = _scenario_file(tmp_path)
    scen = load(scen_file)
    with sitl(scen, speedup=5.0) as first, UdpRelay(first.ports[0]) as relay:
        with CompanionProcess(tmp_path, relay.port, scen_file) as comp:
            # Long enough that the new vehicle's clock (from 0) is clearly behind: a reboot, not reordering.
            _until(
                lambda: first.vehicle(0).counters.setpoints_accepted > 50 and first.runner.clock.sim_s > 15.0,
                30.0,
                "the first vehicle to fly",
            )
            with sitl(scen, speedup=5.0) as second:
                # The vehicle "reboots": same address for the companion, a new autopilot whose clock starts at 0.
                relay.switch_upstream(second.ports[0])
                first.stop()
                _until(
                    lambda: second.vehicle(0).in_loop and second.vehicle(0).counters.setpoints_accepted > 20,
                    30.0,
                    "the restarted vehicle to be armed in GUIDED and flown",
                )
                second.stop()
            comp.proc.send_signal(signal.SIGTERM)
            code, _ = comp.wait(15)
            assert code == 0
            status = comp.status()
            assert "restarted" in comp.log()
    assert status["counters"]["restarts"] == 1 and status["counters"]["engagements"] == 2


@pytest.fixture(scope="module")
def tiny_checkpoint(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A decoy checkpoint from ``python -m tssac_core.train`` with tiny settings (untrained, action_repeat 5)."""
    out = tmp_path_factory.mktemp("train") / "run"
    train = subprocess.run(
        [
            sys.executable,
            "-m",
            "tssac_core.train",
            "--roles",
            "decoy",
            "--epochs",
            "1",
            "--steps-per-epoch",
            "50",
            "--validation-episodes",
            "0",
            "--update-after",
            "1000",
            "--action-repeat",
            "5",
            "--set",
            "hidden_sizes=[16]",
            "--scenario",
            str(STRIKE),
            "--out",
            str(out),
            "--threads",
            "1",
            "--no-progress",
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=_env(),
        timeout=150,
    )
    assert train.returncode == 0, train.stderr
    return out / "decoy.pt"


@pytest.mark.timeout(180)
@pytest.mark.parametrize("grant_s", ["0", "1"])
def test_companion_flies_a_trained_checkpoint_holding_its_actions(
    tmp_path: Path, tiny_checkpoint: Path, grant_s: str
) -> None:
    """action_repeat 5: one decision every 5 ticks, held in between; answered at every tick (``--lockstep-grant-s
    0``), or once per decision with a lockstep grant of the 4 ticks to the next one (tssac_core.wire.lockstep)."""
    model = tiny_checkpoint
    scen_file = _scenario_file(tmp_path)
    argv = ("--model", str(model), "--lockstep", "--duration-s", "3", "--lockstep-grant-s", grant_s)
    with sitl(load(scen_file), **lockstep()) as s, UdpRelay(s.ports[0]) as relay:
        with CompanionProcess(tmp_path, relay.port, scen_file, *argv) as comp:
            code, text = comp.wait(90)
            assert code == 0 and "status=duration" in text, comp.log()
        s.stop()
    setpoints = {m.time_boot_ms: (m.yaw_rate, m.afx) for _, m in relay.sent("SET_POSITION_TARGET_LOCAL_NED")}
    grants = {m.time_boot_ms: m.value for _, m in relay.sent("NAMED_VALUE_INT") if m.name == GRANT_NAME}
    status = json.loads((tmp_path / "decoy.status.json").read_text())
    if grant_s == "0":
        assert sorted(setpoints) == [100 * k for k in range(31)] and grants == {}
        for k in range(31):
            assert setpoints[100 * k] == setpoints[100 * (k - k % 5)]
    else:
        assert sorted(setpoints) == [500 * k for k in range(7)]
        assert grants == {500 * k: 500 * k + 400 for k in range(6)}  # none with the flight's last answer
        assert status["counters"]["ticks_granted"] == 24
    assert status["counters"]["control_steps"] == 31
    spec = scenario().vehicle(Role.DECOY)
    for yaw_rate, afx in setpoints.values():
        assert math.isfinite(yaw_rate) and abs(yaw_rate) <= math.radians(spec.turn_rate_max_deg_s) + 1e-6
        assert abs(afx) <= spec.accel_max_m_s2 + 1e-6
    decisions = {setpoints[100 * k] for k in range(0, 31, 5)}
    assert len(decisions) > 1
    # The first decision is the policy's action on the observation training builds for the start state
    # (noise-free fixes: the filter starts exactly there), so the bridge's observation is training's.
    from tssac_core.deploy.policy import Policy
    from tssac_core.sim.observation import observe
    from tssac_core.sim.routes import RouteMap

    policy = Policy.load(model, Role.DECOY)
    scen = load(scen_file)
    world = World(scen, 1)
    world.reset([0], [scen.layout])
    first = action_to_setpoint(
        tuple(policy.act(observe(snapshot(world), 0, policy.observation_mode, RouteMap())[0])), spec
    )
    assert setpoints[0] == pytest.approx((first.yaw_rate_rad_s, first.accel_m_s2), abs=1e-4)


@pytest.mark.timeout(120)
def test_companion_holds_when_the_policy_returns_nan(tmp_path: Path, tiny_checkpoint: Path) -> None:
    import torch

    data = torch.load(tiny_checkpoint, map_location="cpu", weights_only=False)
    data["actor"] = {
        k: torch.full_like(v, float("nan")) if v.is_floating_point() else v for k, v in data["actor"].items()
    }
    broken = tmp_path / "decoy.pt"
    torch.save(data, broken)
    scen_file = _scenario_file(tmp_path)
    with sitl(load(scen_file), **lockstep()) as s, UdpRelay(s.ports[0]) as relay:
        with CompanionProcess(
            tmp_path, relay.port, scen_file, "--model", str(broken), "--lockstep", "--duration-s", "2"
        ) as comp:
            code, text = comp.wait(90)
            assert code == 0 and "status=duration" in text, comp.log()
            status = comp.status()
        s.stop()
    setpoints = [m for _, m in relay.sent("SET_POSITION_TARGET_LOCAL_NED")]
    assert len(setpoints) == 21 and all(m.yaw_rate == 0.0 and m.afx == 0.0 for m in setpoints)
    assert any("non-finite action, holding" in m.text for _, m in relay.sent("STATUSTEXT"))
    assert status["counters"]["nonfinite_actions"] == 21 and status["counters"]["hold_episodes"] == 1


def test_companion_bad_input_is_one_line_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed\n")
    base = ["--connect", "udpout:127.0.0.1:9", "--role", "decoy"]
    cases = [
        (base + ["--pilot", "guidance", "--scenario", str(bad)], "bad.yaml"),
        (base + ["--pilot", "guidance", "--scenario", str(REPO / "scenarios" / "random.yaml")], "--layout-out"),
        (base + ["--model", str(tmp_path / "none.pt"), "--scenario", str(STRIKE)], "checkpoint not found"),
        (
            ["--connect", "tcp:1.2.3.4:5", "--role", "decoy", "--pilot", "guidance", "--scenario", str(STRIKE)],
            "udpout:HOST:PORT",
        ),
        (base + ["--scenario", str(STRIKE)], "one of the arguments --model --pilot is required"),
    ]
    for argv, needle in cases:
        assert companion_cli.main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and needle in err[0], (argv, err)
    proc = subprocess.run(
        [sys.executable, "-m", "mavlink_bridge.companion", *cases[1][0]],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=_env(),
        timeout=60,
    )
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1 and "--layout-out" in proc.stderr


def test_companion_waits_a_quarter_second_per_command_in_lockstep_and_a_second_otherwise() -> None:
    """A lockstep world holding at its start answers a command at once, so a missing COMMAND_ACK was lost: the
    companion asks again after 0.25 s instead of 1 s; an explicit --command-timeout-s wins either way."""
    base = ["--connect", "udpout:127.0.0.1:9", "--role", "strike", "--pilot", "guidance", "--scenario", str(STRIKE)]

    def timeout_s(*extra: str) -> float:
        args = companion_cli.build_parser().parse_args([*base, *extra])
        return companion_cli.config_from_args(args).command_timeout_s

    assert timeout_s() == 1.0
    assert timeout_s("--lockstep") == 0.25
    assert timeout_s("--lockstep", "--command-timeout-s", "2") == 2.0
    assert timeout_s("--command-timeout-s", "0.5") == 0.5


@pytest.mark.timeout(60)
def test_companion_without_a_vehicle_gives_up_with_exit_3(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    try:
        code = companion_cli.main(
            [
                "--connect",
                f"udpout:127.0.0.1:{silent.getsockname()[1]}",
                "--role",
                "strike",
                "--pilot",
                "guidance",
                "--scenario",
                str(STRIKE),
                "--timeout-s",
                "0.5",
                "--status-json",
                str(tmp_path / "s.json"),
            ]
        )
    finally:
        silent.close()
    assert code == 3
    assert "status=no_vehicle" in capsys.readouterr().out
    assert json.loads((tmp_path / "s.json").read_text())["status"] == "no_vehicle"


def _random_fields(cls: type, rng: np.random.Generator) -> list[object]:
    """Constructor arguments of a pymavlink message class: random values in each field's range, zeros among them
    (so payloads end in zero bytes the packer must cut), strings shorter than their field."""
    args: list[object] = []
    for name, ftype in zip(cls.fieldnames, cls.fieldtypes, strict=True):
        n = cls.array_lengths[cls.ordered_fieldnames.index(name)]

        def one() -> object:
            if rng.random() < 0.3:
                return 0
            if ftype in ("float", "double"):
                return float(rng.normal(0.0, 1e3))
            info = np.iinfo(np.dtype(ftype.removesuffix("_t")))
            return int(rng.integers(int(info.min), int(info.max), endpoint=True, dtype=info.dtype))

        if ftype == "char":
            args.append(bytes(rng.integers(65, 91, size=int(rng.integers(0, max(n, 1) + 1))).astype(np.uint8)))
        elif n:
            args.append([one() for _ in range(n)])
        else:
            args.append(one())
    return args


def _protocol_pair(sysid: int, link_id: int, signed: bool) -> tuple[M.MAVLink, M.MAVLink]:
    """Two pymavlink protocol objects of system ``sysid`` in the same signing state: one whose signing state our packer
    advances, one that packs the expected bytes."""
    pair = (M.MAVLink(None, srcSystem=sysid, srcComponent=1), M.MAVLink(None, srcSystem=sysid, srcComponent=1))
    if signed:
        stamp = now_10us()
        for mav in pair:
            mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.link_id = bytes(range(32)), True, link_id
            mav.signing.timestamp = stamp
    return pair


@pytest.mark.parametrize("signed", [False, True])
def test_frame_packer_makes_pymavlinks_bytes_for_every_message_of_the_dialect(signed: bool) -> None:
    from mavlink_bridge.link.connection import DIALECT
    from tssac_core.wire.framing import FramePacker, scan_frames

    rng = np.random.default_rng(7)
    packer = FramePacker(DIALECT.crc16)
    ours, theirs = _protocol_pair(3, 203, signed)
    for _ in range(3):
        for cls in M.mavlink_map.values():
            msg = cls(*_random_fields(cls, rng))
            seq = int(rng.integers(0, 256))
            theirs.seq = seq
            expected = bytes(msg.pack(theirs))
            frame = packer.pack(msg, seq, 3, 1, ours.signing)
            assert frame == expected, cls.msgname
            assert ours.signing.timestamp == theirs.signing.timestamp
            assert scan_frames(frame, DIALECT).frames == [frame]  # and the scanner takes it


@pytest.mark.parametrize("signed", [False, True])
def test_frame_packer_packs_fields_as_pymavlink_packs_the_message(signed: bool) -> None:
    """pack_fields (class + constructor arguments, no message object) against pymavlink's own pack, for every message
    without strings and arrays: those whose wire order differs from the constructor's included."""
    from mavlink_bridge.link.connection import DIALECT
    from tssac_core.wire.framing import FramePacker

    rng = np.random.default_rng(11)
    packer = FramePacker(DIALECT.crc16)
    ours, theirs = _protocol_pair(2, 0, signed)
    flat = [c for c in M.mavlink_map.values() if set(c.lengths) == {1} and "char" not in c.fieldtypes]
    assert any(c.orders != sorted(c.orders) for c in flat)  # reordering is exercised
    for _ in range(3):
        for cls in flat:
            fields = _random_fields(cls, rng)
            seq = int(rng.integers(0, 256))
            theirs.seq = seq
            expected = bytes(cls(*fields).pack(theirs))
            assert packer.pack_fields(cls, fields, seq, 2, 1, ours.signing) == expected, cls.msgname
            assert ours.signing.timestamp == theirs.signing.timestamp
    with pytest.raises(ValueError, match="STATUSTEXT"):
        packer.pack_fields(M.MAVLink_statustext_message, [6, b"hi", 0, 0], 0, 2, 1)


def test_crc16_is_mavlinks_x25_checksum_with_or_without_fastcrc() -> None:
    from tssac_core.wire.framing import crc16_mcrf4xx, crc16_mcrf4xx_python

    rng = np.random.default_rng(3)
    for n in (0, 1, 2, 9, 63, 280):
        data = rng.integers(0, 256, size=n).astype(np.uint8).tobytes()
        assert crc16_mcrf4xx(data) == crc16_mcrf4xx_python(data) == M._x25crc_slow(data).crc
    assert crc16_mcrf4xx_python(b"123456789") == 0x6F91  # CRC-16/MCRF4XX's check value


@pytest.mark.parametrize("signed", [False, True])
def test_frame_decoder_makes_pymavlinks_objects_for_every_message_of_the_dialect(signed: bool) -> None:
    from mavlink_bridge.link.connection import DIALECT
    from tssac_core.wire.framing import FrameDecoder, scan_frames

    rng = np.random.default_rng(5)
    decoder = FrameDecoder(M.mavlink_map, M.MAVLink_header)
    sender = M.MAVLink(None, srcSystem=2, srcComponent=1)
    if signed:
        sender.signing.secret_key, sender.signing.sign_outgoing, sender.signing.link_id = bytes(32), True, 7
        sender.signing.timestamp = now_10us()
    for _ in range(3):
        for cls in M.mavlink_map.values():
            sender.seq = int(rng.integers(0, 256))
            frame = bytes(cls(*_random_fields(cls, rng)).pack(sender))
            assert scan_frames(frame, DIALECT).frames == [frame]
            expected = M.MAVLink(None, srcSystem=255, srcComponent=191).decode(bytearray(frame))
            got = decoder.decode(frame)
            assert type(got) is type(expected)
            header = vars(got).pop("_header")
            assert vars(header) == vars(vars(expected).pop("_header"))
            assert vars(got) == vars(expected), cls.msgname


def test_frame_decoder_reads_a_payload_longer_than_its_message_as_pymavlink_does() -> None:
    """A frame from a dialect with more extension fields than ours: its payload is longer than the message's struct;
    both decoders read the struct's bytes and keep the whole payload in ``_payload``."""
    from mavlink_bridge.link.connection import DIALECT
    from tssac_core.wire.framing import FrameDecoder, scan_frames

    decoder = FrameDecoder(M.mavlink_map, M.MAVLink_header)
    for msg in (
        M.MAVLink_local_position_ned_message(1500, 1.0, -2.0, 3.0, 4.0, -5.0, 6.0),
        M.MAVLink_heartbeat_message(1, 3, 4, 5, 6, 3),
    ):
        frame = bytearray(msg.pack(M.MAVLink(None, srcSystem=2, srcComponent=1)))
        payload = frame[10:-2] + bytes((7, 8, 9))  # three bytes of fields we do not know
        header = bytes((frame[0], len(payload))) + frame[2:10]
        crc = DIALECT.crc16(header[1:] + payload + bytes((type(msg).crc_extra,)))
        longer = bytes(header + payload + crc.to_bytes(2, "little"))
        assert scan_frames(longer, DIALECT).frames == [longer]
        expected = M.MAVLink(None, srcSystem=255, srcComponent=191).decode(bytearray(longer))
        got = decoder.decode(longer)
        assert vars(vars(got).pop("_header")) == vars(vars(expected).pop("_header"))
        assert vars(got) == vars(expected)
        assert [getattr(got, name) for name in msg.get_fieldnames()] == [
            getattr(msg, name) for name in msg.get_fieldnames()
        ]
