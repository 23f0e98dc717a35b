"""Attacks and faults (issue 28) against the SITL vehicles and a companion, over real UDP on 127.0.0.1.

Signing that cannot be poisoned (a frame's timestamp counts only once its signature verifies), no
telemetry for anyone without the key, bounded client and monitor tables, absurd message intervals,
garbage headers in front of valid frames, lockstep over a lossy, slow link in simulated time, and a
companion that hears only its vehicle's address and, with signing, only correctly signed frames (a
forged MSN_END ends nothing). Real MAVLink bytes built with pymavlink, no mocks. Every wait is bounded;
the attack figures before and after the fixes: benchmarks/bench_attacks.py.
"""

from __future__ import annotations

import math
import os
import re
import signal
import socket
import sys
import time
from pathlib import Path

import pytest
from sitl_helpers import GUIDED, STRIKE, Client, RunningSitl, lockstep, mavlink2, scenario, sitl, wait_until
from test_bridge import CompanionProcess, UdpRelay, _scenario_file

from mavlink_bridge.fly.mission_runner import child_failure
from mavlink_bridge.link.connection import MavLink
from mavlink_bridge.processes.children import ChildProcesses
from sim_vehicles.__main__ import main as sitl_main
from sim_vehicles.link.link_model import LinkChannel, keyed_uniforms
from sim_vehicles.link.mavlink_io import MAX_MONITORS, MAX_PEERS, MONITOR_BYTES_PER_S
from tssac_core.sim.scenario import LinkModel, ScenarioError, load
from tssac_core.sim.sitl_config import ClockMode, LockstepStart
from tssac_core.wire.signing import SignatureVerifier, Verdict, companion_link_id, now_10us
from tssac_core.wire.truth_log_schema import read_truth_log

M = mavlink2
KEY = bytes(range(32))
WRONG_KEY = bytes(32)
ONE_YEAR_10US = 365 * 24 * 3600 * 100_000


def _signed(msg: mavlink2.MAVLink_message, sysid: int, compid: int, link_id: int, key: bytes, stamp_10us: int) -> bytes:
    """``msg`` packed as system (sysid, compid), signed with ``key`` on ``link_id`` at ``stamp_10us``."""
    mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.signing.secret_key = key
    mav.signing.sign_outgoing = True
    mav.signing.link_id = link_id
    mav.signing.timestamp = stamp_10us
    return bytes(msg.pack(mav))


def _heartbeat() -> mavlink2.MAVLink_message:
    return M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)


def _request_home() -> mavlink2.MAVLink_message:
    return M.MAVLink_command_long_message(
        1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, M.MAVLINK_MSG_ID_HOME_POSITION, 0, 0, 0, 0, 0, 0
    )


class _Raw:
    """A bare UDP socket: sends exactly the bytes given, collects whatever comes back."""

    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.dest = ("127.0.0.1", port)

    def send(self, data: bytes) -> None:
        self.sock.sendto(data, self.dest)

    def received_bytes(self, duration_s: float) -> int:
        total, deadline = 0, time.monotonic() + duration_s
        while time.monotonic() < deadline:
            try:
                total += len(self.sock.recv(65535))
            except TimeoutError:
                pass
        return total

    def close(self) -> None:
        self.sock.close()


# ------------------------------------------------------------------------------ the verifier


def test_verifier_checks_the_signature_before_believing_the_timestamp() -> None:
    v = SignatureVerifier(KEY)
    now = now_10us()
    genuine = [_signed(_heartbeat(), 255, 190, 1, KEY, now + i) for i in range(3)]
    assert v.check(genuine[0]) is Verdict.OK
    # A far-future frame on the same stream with the wrong key: refused, and the stream's clock unchanged.
    for i in range(5):
        assert v.check(_signed(_heartbeat(), 255, 190, 1, WRONG_KEY, now + ONE_YEAR_10US + i)) is Verdict.BAD_SIGNATURE
    assert v.streams[(1, 255, 190)] == now
    assert v.check(genuine[1]) is Verdict.OK and v.check(genuine[2]) is Verdict.OK
    assert v.check(genuine[1]) is Verdict.REPLAYED  # byte-identical replay
    # A new stream more than a minute old is a replay; unsigned frames are unsigned; a flipped bit is a bad signature.
    assert v.check(_signed(_heartbeat(), 7, 1, 0, KEY, now - 7_000_000)) is Verdict.REPLAYED
    assert v.check(bytes(_heartbeat().pack(mavlink2.MAVLink(None, srcSystem=9)))) is Verdict.UNSIGNED
    tampered = bytearray(_signed(_heartbeat(), 255, 190, 2, KEY, now + 10))
    tampered[12] ^= 1
    assert v.check(bytes(tampered)) is Verdict.BAD_SIGNATURE
    assert (v.counters.ok, v.counters.bad_signature, v.counters.replayed, v.counters.unsigned) == (3, 6, 2, 1)


# -------------------------------------------------------------------------- signing on a vehicle


@pytest.mark.timeout(30)
@pytest.mark.parametrize("forged", ["heartbeat", "command", "same_port"])
def test_forged_far_future_frames_never_lock_the_signed_client_out(forged: str) -> None:
    with sitl(speedup=5.0, signing_key=KEY) as s, Client(s.ports[0], key=KEY) as good:
        endpoint = s.endpoint(0)
        good.connect()
        link_id = good.mav.signing.link_id
        msg = _request_home() if forged == "command" else _heartbeat()
        frames = [_signed(msg, 255, 190, link_id, WRONG_KEY, now_10us() + ONE_YEAR_10US + i) for i in range(50)]
        evil = _Raw(s.ports[0])
        try:
            for f in frames:
                (good.conn.write if forged == "same_port" else evil.send)(f)
            assert wait_until(lambda: endpoint.rx.bad_signature >= 50, 2.0)
            assert evil.received_bytes(0.3) == 0
        finally:
            evil.close()
        for _ in range(5):  # every genuine command still gets through
            assert good.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION, retries=1) is not None
        assert endpoint.rx.replayed == 0 and len(endpoint.peers) == 1
        s.stop()


@pytest.mark.timeout(30)
def test_no_telemetry_without_the_key_by_default() -> None:
    with sitl(speedup=5.0, signing_key=KEY) as s:
        endpoint = s.endpoint(0)
        unsigned, wrong = _Raw(s.ports[0]), _Raw(s.ports[0])
        try:
            for _ in range(3):
                unsigned.send(bytes(_heartbeat().pack(mavlink2.MAVLink(None, srcSystem=255))))
                wrong.send(_signed(_heartbeat(), 255, 190, 1, WRONG_KEY, now_10us()))
            assert unsigned.received_bytes(1.0) == 0 and wrong.received_bytes(0.2) == 0
            assert endpoint.rx.unsigned_rejected == 3 and endpoint.rx.bad_signature == 3
            assert not endpoint.peers and not endpoint.monitors
        finally:
            unsigned.close()
            wrong.close()
        s.stop()


@pytest.mark.timeout(30)
def test_unsigned_monitors_only_when_allowed_bounded_and_never_obeyed() -> None:
    with sitl(speedup=5.0, signing_key=KEY, unsigned_monitors=True) as s:
        v, endpoint = s.vehicle(0), s.endpoint(0)
        monitors = [Client(s.ports[0]) for _ in range(MAX_MONITORS + 2)]
        wrong = _Raw(s.ports[0])
        try:
            for m in monitors:
                m.heartbeat()
            wrong.send(_signed(_heartbeat(), 255, 190, 1, WRONG_KEY, now_10us()))
            assert wait_until(lambda: len(endpoint.monitors) == MAX_MONITORS and endpoint.rx.peers_refused >= 2, 2.0)
            first = monitors[0]
            assert first.wait_type("HEARTBEAT", 2.0) is not None  # it can watch
            assert first.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, timeout_s=0.3, retries=2) is None  # not command
            assert not v.armed and wrong.received_bytes(0.2) == 0  # a wrong signature is never a monitor's
            # Bounded telemetry: at most the budget per second (plus one second's burst).
            first.conn.port.setblocking(False)
            got = _drain_bytes(first.conn.port, 2.0)
            assert 0 < got <= 3 * MONITOR_BYTES_PER_S
            assert endpoint.tx.monitor_throttled > 0
        finally:
            for m in monitors:
                m.close()
            wrong.close()
        s.stop()


def _drain_bytes(sock: socket.socket, duration_s: float) -> int:
    total, deadline = 0, time.monotonic() + duration_s
    while time.monotonic() < deadline:
        try:
            total += len(sock.recv(65535))
        except BlockingIOError:
            time.sleep(0.01)
    return total


@pytest.mark.timeout(30)
def test_client_table_is_bounded_and_the_first_client_keeps_its_service() -> None:
    with sitl(speedup=5.0) as s, Client(s.ports[0]) as good:
        endpoint = s.endpoint(0)
        good.connect()
        crowd = [_Raw(s.ports[0]) for _ in range(MAX_PEERS + 20)]
        try:
            for c in crowd:
                c.send(bytes(_heartbeat().pack(mavlink2.MAVLink(None, srcSystem=200))))
            assert wait_until(lambda: endpoint.rx.peers_refused >= 21, 2.0)
            assert len(endpoint.peers) == MAX_PEERS
            assert good.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION) is not None
        finally:
            for c in crowd:
                c.close()
        s.stop()


def test_verifiers_sharing_a_table_refuse_a_frame_another_one_accepted_once_its_stream_moved_on() -> None:
    shared: dict[tuple[int, int, int], tuple[int, object]] = {}
    decoy, detect = SignatureVerifier(KEY, shared), SignatureVerifier(KEY, shared)
    now = now_10us()
    station, spy = ("127.0.0.1", 14550), ("127.0.0.1", 40000)
    frames = [_signed(_heartbeat(), 255, 190, 7, KEY, now + i) for i in range(3)]
    assert all(decoy.check(f, sender=station) is Verdict.OK for f in frames)
    assert detect.check(frames[0], sender=station) is Verdict.REPLAYED  # older than what decoy accepted
    assert detect.check(frames[2], sender=spy) is Verdict.REPLAYED  # the same frame from another address: at once
    assert detect.check(frames[2], sender=station) is Verdict.OK  # from its sender: the station's own fan-out
    later = _signed(_heartbeat(), 255, 190, 7, KEY, now + 10)
    assert detect.check(later, sender=spy) is Verdict.OK  # newer than anything: the station back on a new port
    assert decoy.check(later, sender=station) is Verdict.REPLAYED  # ... which now owns its stream
    assert SignatureVerifier(KEY).check(frames[0]) is Verdict.OK  # an unshared table knows nothing of decoy's


@pytest.mark.timeout(60)
@pytest.mark.parametrize("delay_s", [0.0, 0.2, 3.0])
def test_a_ground_stations_frame_replayed_to_another_vehicle_gives_a_keyless_spy_nothing(delay_s: float) -> None:
    """Issue 61, item 4: one signed HEARTBEAT of a ground station (link id 7, bound to no vehicle) captured on its
    way to the decoy and sent to the detect UAV at once, 0.2 s or 3 s later, the station sending nothing after it:
    not a byte for the spy (before, it got telemetry: 204 positions in 10 s). The station's own fan-out of one frame
    to all three vehicles, from its one socket, is served by each."""
    with sitl(speedup=5.0, signing_key=KEY) as s:
        station = _Raw(s.ports[0])
        try:
            frame = _signed(_heartbeat(), 255, 190, 7, KEY, now_10us())
            station.send(frame)
            assert station.received_bytes(0.5) > 0  # the decoy serves the station
            time.sleep(delay_s)
            assert _spy_bytes(s.ports[1], [frame]) == 0
            assert s.endpoint(1).rx.replayed >= 1 and not s.endpoint(1).peers
            fan_out = _signed(_heartbeat(), 255, 190, 7, KEY, now_10us())
            for port in s.ports:
                station.dest = ("127.0.0.1", port)
                station.send(fan_out)
            assert wait_until(lambda: all(len(s.endpoint(i).peers) == 1 for i in range(3)), 2.0)
        finally:
            station.close()
        s.stop()


def _spy_bytes(port: int, frames: list[bytes], duration_s: float = 2.0) -> int:
    spy = _Raw(port)
    try:
        for frame in frames:
            spy.send(frame)
        return spy.received_bytes(duration_s)
    finally:
        spy.close()


@pytest.mark.slow
@pytest.mark.timeout(60)
def test_replay_across_vehicles_gives_a_keyless_spy_nothing() -> None:
    """Signed frames captured on their way to or from the decoy, sent to the detect UAV (or back to the decoy) a
    few seconds later or at once: not a byte for the spy, and both companions keep their service."""
    with sitl(speedup=5.0, signing_key=KEY) as s, UdpRelay(s.ports[0]) as relay:
        links = [
            MavLink(f"udpout:127.0.0.1:{relay.port}", signing_key=KEY, signing_link_id=companion_link_id(1)),
            MavLink(f"udpout:127.0.0.1:{s.ports[1]}", signing_key=KEY, signing_link_id=companion_link_id(2)),
        ]
        try:

            def talk(duration_s: float) -> None:
                deadline = time.monotonic() + duration_s
                while time.monotonic() < deadline:
                    for link in links:
                        link.send_heartbeat()
                        while link.recv(0.0) is not None:
                            pass
                    time.sleep(0.1)

            for link in links:
                link.wait_heartbeat(5.0)
            talk(0.5)
            captured = [bytes(m.get_msgbuf()) for _, m in relay.to_vehicle if m.get_type() == "HEARTBEAT"]
            talk(3.0)
            assert _spy_bytes(s.ports[1], captured[:1]) == 0  # a few seconds later
            links[0].send_heartbeat()
            assert wait_until(lambda: relay.to_vehicle[-1][1].get_type() == "HEARTBEAT", 1.0)
            newest = bytes(relay.to_vehicle[-1][1].get_msgbuf())
            assert _spy_bytes(s.ports[1], [newest]) == 0  # at once, before the decoy's stream moves on
            telemetry = [bytes(m.get_msgbuf()) for _, m in relay.to_companion[-20:]]
            assert _spy_bytes(s.ports[0], telemetry) == 0  # the decoy's own frames reflected back to it
            assert _spy_bytes(s.ports[1], telemetry) == 0  # ... or sent to another vehicle
            for link in links:
                assert link.arm().result == M.MAV_RESULT_ACCEPTED  # the genuine companions are not locked out
            detect = s.endpoint(1)
            assert detect.rx.wrong_link >= 2 and detect.rx.from_vehicles >= 1 and len(detect.peers) == 1
            assert s.endpoint(0).rx.from_vehicles >= 1 and len(s.endpoint(0).peers) == 1
        finally:
            for link in links:
                link.close()
        s.stop()


# ---------------------------------------------------------------------------- smaller faults


@pytest.mark.timeout(30)
def test_absurd_message_intervals_are_refused_and_get_always_answers() -> None:
    with sitl(speedup=5.0) as s, Client(s.ports[0]) as c:
        v = s.vehicle(0)
        c.connect()
        for interval_us in (3e38, -5.0, math.inf, -math.inf, math.nan, 2.0**31, 1e12):
            ack = c.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, interval_us)
            assert ack is not None and ack.result == M.MAV_RESULT_DENIED, interval_us
        ack = c.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, 2e9)  # 33 min: long, but reportable
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        ack = c.command(M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        assert (
            c.wait_type("MESSAGE_INTERVAL", 1.0, message_id=M.MAVLINK_MSG_ID_ATTITUDE, interval_us=2_000_000_000)
            is not None
        )
        assert v.counters.handler_errors == 0
        s.stop()


@pytest.mark.timeout(30)
def test_garbage_header_with_unknown_id_does_not_hide_the_next_frame() -> None:
    with sitl(speedup=5.0) as s, Client(s.ports[0]) as c:
        endpoint = s.endpoint(0)
        c.connect()
        for n in range(3):
            valid = bytes(_request_home().pack(c.mav))
            # Claims an unknown message id (0xEEEEEE) and a length that covers the valid frame behind it.
            garbage = bytes([0xFD, len(valid) - 2, 0, 0, 0, 1, 1, 0xEE, 0xEE, 0xEE])
            c.conn.write(garbage + valid)
            assert c.wait_type("COMMAND_ACK", 1.0, command=M.MAV_CMD_REQUEST_MESSAGE) is not None, n
        assert endpoint.rx.unknown_id >= 3
        s.stop()


# ------------------------------------------------------------------- lockstep with a lossy link


def test_keyed_link_draws_do_not_depend_on_other_traffic() -> None:
    import numpy as np

    model = LinkModel(packet_loss=0.3, latency_ms=200.0)
    fates = []
    for extra in (0, 7):
        ch: LinkChannel[int] = LinkChannel(model, np.random.default_rng(3))
        for i in range(extra):
            ch.push(0.0, -1)  # unkeyed traffic (heartbeats) in between
        for k in range(200):
            ch.push(float(k), k, key=k)
        fates.append(sorted(x for x in ch.pop_due(1e9) if x >= 0))
    assert fates[0] == fates[1] and 100 < len(fates[0]) < 180
    assert keyed_uniforms(1, 2) == keyed_uniforms(1, 2) != keyed_uniforms(1, 3)


def _fly_lockstep(steps: int, seed: int, truth_log: Path) -> tuple[int, int]:
    """A client answering every tick of vehicle 0 over a 30%-loss, 200 ms link: (steps flown, failsafes)."""
    link = LinkModel(gps_position_sigma_m=0.0, gps_velocity_sigma_m_s=0.0, packet_loss=0.3, latency_ms=200.0)
    # GUID_TIMEOUT 2 s: a step held for a lost setpoint would end in the wall-clock failsafe.
    with (
        sitl(scenario(link), seed=seed, setpoint_timeout_s=2.0, truth_log=truth_log, **lockstep()) as s,
        Client(s.ports[0]) as c,
    ):
        v = s.vehicle(0)
        c.connect(timeout_s=10.0)
        # 30% loss each way: a command and its ACK both get through about half the time.
        assert c.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, timeout_s=0.5, retries=20) is not None
        assert (
            c.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED, timeout_s=0.5, retries=20)
            is not None
        )
        t0 = time.monotonic()
        answered: set[int] = set()
        while s.runner.world.steps[0] < steps and time.monotonic() < t0 + 20.0:
            msg = c.poll(0.05)
            if msg is not None and msg.get_type() == "SYSTEM_TIME" and msg.time_boot_ms not in answered:
                answered.add(msg.time_boot_ms)
                c.setpoint(0.04 * math.sin(msg.time_boot_ms / 3000.0), 1.0, stamp_ms=msg.time_boot_ms)
        flown, failsafes = int(s.runner.world.steps[0]), v.counters.failsafes
        s.stop()
    return flown, failsafes


@pytest.mark.timeout(90)
def test_lockstep_over_a_lossy_slow_link_runs_in_simulated_time_and_repeats(tmp_path: Path) -> None:
    steps = 100
    runs = [_fly_lockstep(steps, 4, tmp_path / f"truth{i}.jsonl") for i in range(2)]
    # No step waits for a lost setpoint (30 of them would take 60 s of wall-clock failsafes) and nothing fails safe.
    assert all(flown >= steps and failsafes == 0 for flown, failsafes in runs), runs
    # Same seed, same flight: the decoy's states and the commands it flew, step by step.
    tracks = []
    for i in range(2):
        rows = [r for r in read_truth_log(tmp_path / f"truth{i}.jsonl") if r["type"] == "step" and r["step"] <= steps]
        tracks.append(
            [
                (
                    r["step"],
                    r["vehicles"]["decoy"]["x_m"],
                    r["vehicles"]["decoy"]["phi_rad"],
                    r["vehicles"]["decoy"]["omega_cmd"],
                )
                for r in rows
            ]
        )
    assert len(tracks[0]) == steps and tracks[0] == tracks[1]
    # The link acted: some commands flown late or never (a step flown on the previous command).
    omegas = [t[3] for t in tracks[0]]
    assert sum(1 for a, b in zip(omegas, omegas[1:]) if a == b) > 10


def _fly_three_engaging_in_turn(order: tuple[int, ...], steps: int, truth_log: Path) -> None:
    """Three clients over a 30%-loss, 200 ms link engage one after the other in ``order`` (the last one's answer to
    tick 0 opens the start gate), then answer every tick of their vehicle with a setpoint of its own."""
    link = LinkModel(gps_position_sigma_m=0.0, gps_velocity_sigma_m_s=0.0, packet_loss=0.3, latency_ms=200.0)
    with sitl(scenario(link), seed=4, setpoint_timeout_s=2.0, truth_log=truth_log, clock=ClockMode.LOCKSTEP) as s:
        clients = [Client(port) for port in s.ports]
        try:
            newest = [-1, -1, -1]

            def answer(i: int, msg: mavlink2.MAVLink_message | None) -> None:
                if msg is not None and msg.get_type() == "SYSTEM_TIME" and msg.time_boot_ms > newest[i]:
                    newest[i] = msg.time_boot_ms
                    clients[i].setpoint(0.02 * (i + 1) * math.sin(newest[i] / 3000.0), 1.0, stamp_ms=newest[i])

            for i in order:
                c = clients[i]
                c.connect(timeout_s=10.0)
                assert c.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, timeout_s=0.3, retries=30) is not None
                ack = c.command(
                    M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED, timeout_s=0.3, retries=30
                )
                assert ack is not None
                ticks = [m for m in c.log if m.get_type() == "SYSTEM_TIME"]
                assert ticks, "no tick before the mode change"
                answer(i, ticks[-1])
                time.sleep(0.3)  # the next client engages clearly later
            deadline = time.monotonic() + 30.0
            while s.runner.world.steps[0] < steps and time.monotonic() < deadline:
                for i, c in enumerate(clients):
                    answer(i, c.poll(0.002))
            assert s.runner.world.steps[0] >= steps
            s.stop()
        finally:
            for c in clients:
                c.close()


@pytest.mark.slow
@pytest.mark.timeout(120)
def test_a_lossy_slow_lockstep_start_does_not_depend_on_which_client_answers_last(tmp_path: Path) -> None:
    """The start gate opens on the last client's answer, which reaches the socket at a time the wall clock chose:
    it crosses the link before the first step, as the earlier answers did, so the flight is the same whoever came
    last."""
    steps = 60
    runs = []
    for k, order in enumerate([(0, 1, 2), (2, 1, 0)]):
        _fly_three_engaging_in_turn(order, steps, tmp_path / f"truth{k}.jsonl")
        rows = [r for r in read_truth_log(tmp_path / f"truth{k}.jsonl") if r["type"] == "step" and r["step"] <= steps]
        runs.append([(r["step"], r["vehicles"]) for r in rows])
    assert len(runs[0]) == steps and runs[0] == runs[1]


# ------------------------------------------------------------------------------- the companion


def _flying(s: RunningSitl, timeout_s: float = 60.0) -> None:
    assert wait_until(lambda: s.vehicle(0).in_loop and s.endpoint(0).peers, timeout_s), "the companion did not engage"


@pytest.mark.timeout(180)
def test_companion_hears_only_its_vehicle_a_forged_mission_end_changes_nothing(tmp_path: Path) -> None:
    scen_file = _scenario_file(tmp_path)
    with sitl(load(scen_file), setpoint_timeout_s=5.0, **lockstep()) as s:
        endpoint = s.endpoint(0)
        with CompanionProcess(tmp_path, s.ports[0], scen_file, "--lockstep", "--duration-s", "8") as comp:
            _flying(s)
            (companion,) = endpoint.peers
            evil = _Raw(companion[1])
            forger = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)  # the vehicle's ids, another port
            try:
                evil.send(bytes(forger.named_value_int_encode(10_000_000, b"MSN_END", 1).pack(forger)))
                evil.send(bytes(forger.named_value_int_encode(10_000_000, b"HIT", 1).pack(forger)))
                evil.send(bytes(forger.statustext_encode(M.MAV_SEVERITY_INFO, b"Mission end: success").pack(forger)))
            finally:
                evil.close()
            code, out = comp.wait(120)
            assert code == 0 and "status=duration" in out, comp.log()
            status = comp.status()
        s.stop()
    assert status["link"]["foreign_rx"] == 3


@pytest.mark.timeout(180)
def test_unsigned_companion_flies_on_through_a_mission_end_spoofed_from_the_vehicles_address(tmp_path: Path) -> None:
    """Signing off, the forger sends from the vehicle's own address (the relay's port) with the vehicle's ids:
    HIT, MSN_END and both texts, and even a POWEROFF heartbeat. The vehicle keeps reporting ACTIVE, so the
    companion keeps flying it to its own end; and a genuine end (the vehicle's POWEROFF, then silence) ends it."""
    scen_file = _scenario_file(tmp_path)
    # Real time at 5x: 20 s of flight last 4 wall seconds, longer than the companion's 2 s POWEROFF confirmation. The
    # world holds at its start until the companion has engaged (hold_start): a companion slow to start on a loaded
    # machine must not find its 20 s almost spent when the forger sends (it once did, and flew to its end before the
    # 0.5 s grace could refute the claim). The setpoint timeout (10 s, 2 wall seconds) is what "controlled throughout"
    # below is measured against: a gap that long is a companion that stopped, not a loaded machine's scheduling (5 s,
    # one wall second, tripped once with three test workers and two training jobs on two cores).
    hold = {"hold_start": True, "lockstep_start": LockstepStart.ANY}
    with sitl(load(scen_file), setpoint_timeout_s=10.0, speedup=5.0, **hold) as s, UdpRelay(s.ports[0]) as relay:
        v = s.vehicle(0)
        with CompanionProcess(tmp_path, relay.port, scen_file, "--duration-s", "20") as comp:
            _flying(s)
            assert relay.companion is not None
            forger = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
            forged = [
                forger.named_value_int_encode(10_000_000, b"HIT", 1),
                forger.named_value_int_encode(10_000_000, b"MSN_END", 1),
                forger.statustext_encode(M.MAV_SEVERITY_NOTICE, b"Target hit"),
                forger.statustext_encode(M.MAV_SEVERITY_NOTICE, b"Mission end: success"),
                forger.heartbeat_encode(
                    M.MAV_TYPE_FIXED_WING, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, M.MAV_STATE_POWEROFF
                ),
            ]
            for msg in forged:
                relay.down.sendto(bytes(msg.pack(forger)), relay.companion)
            code, out = comp.wait(120)
            assert code == 0 and "status=duration" in out, comp.log()
            status = comp.status()
        assert v.counters.failsafes == 0  # controlled throughout: no setpoint gap
        s.stop()
    assert status["counters"]["ends_refuted"] == 1 and status["vehicle_time_s"] >= 20.0


@pytest.mark.timeout(180)
def test_signed_companion_refuses_forgeries_on_the_vehicles_own_address_and_stream(tmp_path: Path) -> None:
    scen_file = _scenario_file(tmp_path)
    key_file = tmp_path / "key.bin"
    key_file.write_bytes(KEY)
    with (
        sitl(load(scen_file), setpoint_timeout_s=5.0, signing_key=KEY, **lockstep()) as s,
        UdpRelay(s.ports[0]) as relay,
    ):
        with CompanionProcess(
            tmp_path, relay.port, scen_file, "--lockstep", "--duration-s", "8", "--signing-key", str(key_file)
        ) as comp:
            _flying(s)
            assert relay.companion is not None
            # From the relay's port, i.e. the vehicle's address as the companion sees it; the vehicle's stream
            # (link 0, system 1, component 1); a wrong key; timestamps a year ahead.
            future = now_10us() + ONE_YEAR_10US
            hb = M.MAVLink_heartbeat_message(M.MAV_TYPE_FIXED_WING, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0, 3)
            end = M.MAVLink_named_value_int_message(10_000_000, b"MSN_END", 1)
            for i, msg in enumerate([hb, hb, hb, end]):
                relay.down.sendto(_signed(msg, 1, 1, 0, WRONG_KEY, future + i), relay.companion)
            unsigned_end = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
            relay.down.sendto(bytes(end.pack(unsigned_end)), relay.companion)
            code, out = comp.wait(120)
            assert code == 0 and "status=duration" in out, comp.log()
            link = comp.status()["link"]
        s.stop()
    # Flew its 8 s to the end (a poisoned stream would have left it deaf: `lost` after 10 s), refused exactly the
    # forgeries, and no genuine frame of the vehicle's was taken for a replay.
    assert link["bad_signature_rx"] == 4 and link["unsigned_rx"] == 1 and link["replayed_rx"] == 0


# ------------------------------------------------------------------------------------- fly


@pytest.mark.timeout(60)
def test_fly_says_which_child_died_how_and_its_last_words(tmp_path: Path) -> None:
    children = ChildProcesses(grace_s=2.0)
    script = (
        "import logging, sys, time\n"
        "logging.basicConfig(format='%(levelname)s %(name)s: %(message)s')\n"
        "log = logging.getLogger('decoy')\n"
        "log.warning('link silent 2.0 s: sending the hold setpoint')\n"
        "print('an ordinary line', file=sys.stderr, flush=True)\n"
        "mode = sys.argv[1]\n"
        "if mode == 'raise': raise ValueError('policy returned a matrix of the wrong shape')\n"
        "if mode == 'exit': sys.exit(3)\n"
        "time.sleep(60)\n"
    )
    try:
        dead = {}
        for mode in ("raise", "exit", "kill", "silent"):
            argv = [sys.executable, "-c", script if mode != "silent" else "import sys; sys.exit(5)", mode]
            dead[mode] = children.start(mode, argv, log_path=tmp_path / f"{mode}.log")
        assert wait_until(lambda: "ordinary" in (tmp_path / "kill.log").read_text(), 20.0)
        os.kill(dead["kill"].pid, signal.SIGKILL)
        assert wait_until(lambda: all(c.poll() is not None for c in dead.values()), 20.0)
        lines = {mode: child_failure(f"companion {mode}", c, c.poll() or 0) for mode, c in dead.items()}
    finally:
        children.stop_all()
    assert lines["raise"].endswith(
        'exited with code 1; its last log line: "ValueError: policy returned a matrix of the wrong shape"'
    )
    assert lines["exit"].endswith(
        'exited with code 3; its last log line: "WARNING decoy: link silent 2.0 s: sending the hold setpoint"'
    )
    assert 'was killed by signal 9 (SIGKILL); its last log line: "WARNING decoy: link silent' in lines["kill"]
    assert lines["silent"].endswith("exited with code 5; its log is empty")
    assert all(ln.startswith(f"companion {m} (pid {dead[m].pid}) ") and "\n" not in ln for m, ln in lines.items())


# ------------------------------------------------------------------------------- scenario files


@pytest.mark.parametrize(
    ("old", "new", "says"),
    [
        ("episode_steps: 4000", "episode_steps: " + "9" * 5000, "a value cannot be read"),
        ("area_km: 100.0", "area_km: " + "9" * 4000, "an integer of 4000 digits"),
        ("area_km: 100.0", "area_km: 1.0e+308", "out of range"),
        ("area_km: 100.0", "area_km: 100000.0", "area_km: must be in (0, 1000]"),
        ("episode_steps: 4000", "episode_steps: 2000000", "episode_steps: must be in 1..1000000"),
        ("cost_limit: 3.0", "cost_limit: .nan", "expected a finite number"),
    ],
)
def test_absurd_numbers_in_a_scenario_are_one_clear_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], old: str, new: str, says: str
) -> None:
    text = STRIKE.read_text()
    assert old in text
    path = tmp_path / "bad.yaml"
    path.write_text(text.replace(old, new))
    with pytest.raises(ScenarioError, match=re.escape(says)) as err:
        load(path)
    assert "\n" not in str(err.value) and len(str(err.value)) < 300
    assert sitl_main(["--scenario", str(path)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("python -m sim_vehicles: error: ") and says in lines[0]
