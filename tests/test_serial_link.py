"""Serial links (issue 59, item 2): the streaming framer against pymavlink's parser, the companion on a real
pseudo-terminal (device strings, busy and missing devices, baud rates), the telemetry budget, and whole missions
over the SITL's serial lines at 57,600 and 921,600 baud, and over a line that drops bytes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sitl_helpers import REPO

from mavlink_bridge.companion import cli as companion_cli
from mavlink_bridge.fly import cli as fly_cli
from mavlink_bridge.link.connection import DIALECT, M, MavLink, parse_connection
from mavlink_bridge.link.guided_commands import SetpointDialect
from mavlink_bridge.link.serial_port import DEFAULT_BAUD, SerialSpec
from mavlink_bridge.link.telemetry_budget import (
    LINE_SHARE,
    check_line,
    companion_streams,
    frame_bytes,
    line_budget,
    stream_bytes_per_s,
)
from sim_vehicles import __main__ as sitl_cli
from sim_vehicles.protocol.streams import DEFAULT_INTERVALS_S
from tssac_core.wire.stream_framing import SequenceGaps, StreamFramer
from tssac_core.wire.uart import UART_BAUDS, bytes_per_s

SHORT = REPO / "scenarios" / "short.yaml"


def _frames(n: int, sysid: int = 1, signed: bool = False) -> list[bytes]:
    """n frames as pymavlink packs them (a mix of sizes), with consecutive sequence numbers."""
    mav = M.MAVLink(None, srcSystem=sysid, srcComponent=1)
    if signed:
        mav.signing.secret_key = bytes(range(32))
        mav.signing.sign_outgoing = True
    out = []
    for i in range(n):
        if i % 3 == 0:
            msg = mav.local_position_ned_encode(100 * i, 1.5 * i, -2.0, 3.0, 250.0, 0.5, 0.0)
        elif i % 3 == 1:
            msg = mav.heartbeat_encode(M.MAV_TYPE_FIXED_WING, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 15, 4)
        else:
            msg = mav.statustext_encode(M.MAV_SEVERITY_INFO, f"frame {i}".encode())
        out.append(bytes(msg.pack(mav)))
        mav.seq = (mav.seq + 1) % 256
    return out


def _pymavlink_frames(stream: bytes) -> list[bytes]:
    """What pymavlink's own parser finds in a byte stream (the reference)."""
    mav = M.MAVLink(None)
    mav.robust_parsing = True
    found = []
    for i in range(len(stream)):
        msg = mav.parse_char(stream[i : i + 1])
        if msg is not None and msg.get_type() != "BAD_DATA":
            found.append(bytes(msg.get_msgbuf()))
    return found


# -------------------------------------------------------------------------------------------------- the framer


@pytest.mark.parametrize("signed", [False, True])
def test_frames_split_anywhere_come_out_whole_and_in_order(signed: bool) -> None:
    """A stream cut into random pieces (1 byte to 200) gives back every frame, as pymavlink's parser does."""
    frames = _frames(60, signed=signed)
    stream = b"".join(frames)
    rng = np.random.default_rng(7)
    framer = StreamFramer(DIALECT)
    got: list[bytes] = []
    i = 0
    while i < len(stream):
        n = int(rng.integers(1, 200))
        got += framer.feed(stream[i : i + n])
        i += n
    assert got == frames == _pymavlink_frames(stream)
    c = framer.counters
    assert (c.frames, c.garbage_bytes, c.bad_crc, c.cut, framer.pending) == (60, 0, 0, 0, 0)


def test_garbage_and_dropped_bytes_are_resynchronised_and_counted() -> None:
    """Noise between frames is skipped; a frame with a byte dropped fails its CRC and the next frame is still found;
    the sequence numbers count the frames lost."""
    frames = _frames(30)
    noise = b"\x00\xfd\x07garbage\xfe\x09"  # start bytes with impossible or cut headers among them
    damaged = frames[10][:7] + frames[10][8:]  # one byte of frame 10 lost on the line
    stream = b"".join(frames[:5]) + noise + b"".join(frames[5:10]) + damaged + b"".join(frames[11:])
    framer = StreamFramer(DIALECT)
    got: list[bytes] = []
    for k in range(0, len(stream), 13):
        got += framer.feed(stream[k : k + 13])
    got += framer.flush()
    assert got == frames[:10] + frames[11:]
    assert framer.counters.garbage_bytes > 0 and framer.counters.bad_crc >= 1
    gaps = SequenceGaps()
    assert sum(gaps.observe(f) for f in got) == 1 == gaps.lost


def test_a_frame_cut_by_an_idle_line_is_dropped_and_what_follows_it_found() -> None:
    frames = _frames(3)
    framer = StreamFramer(DIALECT)
    assert framer.feed(frames[0] + frames[1][:9]) == [frames[0]]
    assert framer.pending == 9
    assert framer.flush() == []  # the line fell idle: the cut frame is gone
    assert framer.counters.cut == 1 and framer.pending == 0
    assert framer.feed(frames[2]) == [frames[2]]


# ------------------------------------------------------------------------------------------ connection strings


def test_serial_connection_strings_are_mavproxys() -> None:
    assert parse_connection("/dev/ttyUSB0,921600") == SerialSpec("/dev/ttyUSB0", 921600)
    assert parse_connection("/dev/serial0") == SerialSpec("/dev/serial0", DEFAULT_BAUD) and DEFAULT_BAUD == 57600
    assert parse_connection("udpout:127.0.0.1:14560").kind == "udpout"  # UDP unchanged
    assert 57600 in UART_BAUDS and 921600 in UART_BAUDS and 57601 not in UART_BAUDS
    for bad in ("/dev/ttyUSB0,57601", "/dev/ttyUSB0,fast", "/dev/ttyUSB0,100000", "ttyUSB0,57600"):
        with pytest.raises(ValueError):
            parse_connection(bad)


def _companion_main(connect: str, *extra: str) -> list[str]:
    return [
        "--connect",
        connect,
        "--role",
        "strike",
        "--pilot",
        "straight",
        "--scenario",
        str(SHORT),
        "--timeout-s",
        "2",
        *extra,
    ]


@pytest.mark.parametrize(
    ("connect", "said"),
    [
        ("/dev/tssac-no-such-port,57600", "serial device /dev/tssac-no-such-port does not exist"),
        ("/dev/null,57601", "baud rate 57601 is not a rate a UART runs at"),
        ("/dev/null,57600", "serial device /dev/null is not a serial line"),
        ("/dev/null,9600", "9600 baud carries 960 bytes/s each way"),
    ],
)
def test_bad_serial_input_is_one_line_and_exit_2(connect: str, said: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert companion_cli.main(_companion_main(connect)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and said in err[0] and "Traceback" not in err[0], err


def test_a_busy_port_is_refused_and_the_holder_keeps_it(capsys: pytest.CaptureFixture[str]) -> None:
    """A second companion on the port a first one holds gets one line and exit 2; the first goes on reading."""
    master, slave = os.openpty()
    device = os.ttyname(slave)
    try:
        with MavLink(f"{device},57600") as first:
            assert companion_cli.main(_companion_main(f"{device},57600")) == 2
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and "is busy: another process has it open" in err[0], err
            hb = _frames(2)[1]
            os.write(master, hb)
            msg = first.recv(2.0)
            assert msg is not None and msg.get_type() == "HEARTBEAT"
    finally:
        os.close(master)
        os.close(slave)


def test_the_link_frames_a_pty_stream_written_in_pieces() -> None:
    """MavLink on a real pseudo-terminal: frames written a few bytes at a time arrive whole, noise is counted, the
    vehicle's sequence gap too; what the link sends comes out on the other side as pymavlink packs it."""
    master, slave = os.openpty()
    device = os.ttyname(slave)
    try:
        with MavLink(f"{device},921600") as link:
            frames = _frames(12)
            stream = b"".join(frames[:6]) + b"\x55\xfd\x01" + b"".join(frames[7:])  # frame 6 lost, noise instead
            for k in range(0, len(stream), 5):
                os.write(master, stream[k : k + 5])
            got = []
            deadline = time.monotonic() + 5.0
            while len(got) < 11 and time.monotonic() < deadline:
                msg = link.recv(0.2)
                if msg is not None:
                    got.append(bytes(msg.get_msgbuf()))
            assert got == frames[:6] + frames[7:]
            c = link.counters
            assert c.frames_lost_rx == 1 and c.garbage_bytes_rx >= 2 and c.bytes_rx == len(stream)
            assert link.send_heartbeat() and link.baud == 921600 and link.line_bytes_per_s == 92160.0
            time.sleep(0.05)
            out = os.read(master, 4096)
            assert _pymavlink_frames(out)[0] == out and out[5:7] == bytes((255, 191))
    finally:
        os.close(master)
        os.close(slave)


def test_the_sitl_and_fly_refuse_a_rate_no_uart_runs_at(capsys: pytest.CaptureFixture[str]) -> None:
    assert sitl_cli.main(["--scenario", str(SHORT), "--base-port", "0", "--serial", "12345"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--serial 12345 is not a rate a UART runs at" in err[0], err
    assert fly_cli.main(["--scenario", str(SHORT), "--pilot", "straight", "--serial", "57601"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--serial 57601 is not a rate a UART runs at" in err[0], err
    missing = ["/dev/tssac-no-such-port,57600"] * 3
    assert fly_cli.main(["--scenario", str(SHORT), "--pilot", "straight", "--connect", *missing]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "serial device /dev/tssac-no-such-port does not exist" in err[0], err


# ------------------------------------------------------------------------------------------------- the budget


def test_the_streams_the_companion_asks_for_fit_57600_with_margin() -> None:
    """At 57,600 baud: what the companion asks for and sends (signed, every dialect, lockstep ticks or not) takes at
    most a quarter of the line each way; and with every stream the bundled vehicle still sends by default once the
    companion has switched off the step-rate ones it does not read (on a serial line it does), under half."""
    line = bytes_per_s(57600)
    assert line == 5760.0
    assert frame_bytes("LOCAL_POSITION_NED", signed=False) == 12 + 28
    for lockstep in (False, True):
        for dialect in SetpointDialect:
            budget = line_budget(57600, companion_streams(0.1, lockstep, dialect), signed=True)
            assert check_line(budget) is None and budget.share < 0.3, budget.describe()
    # The vehicle's defaults, minus what the companion turns off, plus what it asks for.
    names = {mid: M.mavlink_map[mid].msgname for mid in DEFAULT_INTERVALS_S}
    left_on = {
        names[mid]: 1.0 / interval
        for mid, interval in DEFAULT_INTERVALS_S.items()
        if interval is not None and names[mid] not in ("GLOBAL_POSITION_INT", "ATTITUDE", "VFR_HUD")
    }
    left_on.update(companion_streams(0.1, True, SetpointDialect.BODY_RATES).from_vehicle)
    assert stream_bytes_per_s(left_on, signed=True) < LINE_SHARE * line
    # A line too slow for it is refused (below) before the vehicle is touched.
    assert check_line(line_budget(9600, companion_streams(0.1, True, SetpointDialect.ARDUPLANE), True)) is not None


# ------------------------------------------------------------------------------------- missions over serial


def _fly(tmp: Path, name: str, *extra: str) -> dict[str, Any]:
    out = tmp / name
    argv = [sys.executable, "-m", "mavlink_bridge.fly", "--scenario", str(SHORT), "--pilot", "straight"]
    argv += ["--no-progress", "--json", str(out / "fly.json"), "--logs", str(out / "logs"), *extra]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=120, cwd=REPO)
    assert proc.returncode == 0, proc.stderr[-3000:]
    results = json.loads((out / "fly.json").read_text())
    mission = results["missions"][0]
    mdir = out / "logs" / "mission-000"
    statuses = {role: json.loads((mdir / f"{role}.status.json").read_text()) for role in ("decoy", "detect", "strike")}
    summary = json.loads((mdir / "truth.jsonl").read_text().splitlines()[-1])
    serial = {role: counters["serial"] for role, counters in summary["counters"].items()}
    return {"mission": mission, "statuses": statuses, "serial": serial}


# The tests of the flown missions share one test process, so that their module fixture flies them once, not once in
# each process that runs one of them.
flown_missions = pytest.mark.xdist_group("serial_link_missions")
"""The tests of the missions flown over a line: two of them fly in real time (about 30 s of waiting), so they are in
the slow tier (``pytest -m slow``); CI's tier flies a whole mission over serial in tests/test_routing.py."""


@pytest.fixture(scope="module")
def flown(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict[str, Any]]:
    """One mission at 57,600 baud in real time, one at 921,600 in lockstep, one at 57,600 over a line that drops one
    byte in 500 each way."""
    tmp = tmp_path_factory.mktemp("serial")
    return {
        "57600": _fly(tmp, "57600", "--serial", "57600", "--speedup", "1"),
        "921600": _fly(tmp, "921600", "--serial", "921600"),
        "lossy": _fly(tmp, "lossy", "--serial", "57600", "--speedup", "1", "--serial-byte-loss", "0.002"),
    }


@pytest.mark.sitl
@pytest.mark.slow
@flown_missions
@pytest.mark.timeout(240)
@pytest.mark.parametrize("run", ["57600", "921600"])
def test_a_whole_mission_over_a_serial_line_loses_no_frame(flown: dict[str, dict[str, Any]], run: str) -> None:
    """Success, and not one frame lost either way: no garbage, no bad CRC, no cut frame at either framer, no gap in
    the vehicle's sequence numbers, nothing the line's buffer could not hold."""
    r = flown[run]
    assert r["mission"]["success"] is True and r["mission"]["end"] == "success"
    for role, status in r["statuses"].items():
        link = status["link"]
        assert status["status"] == "success", role
        lost = [link[k] for k in ("frames_lost_rx", "garbage_bytes_rx", "bad_data_rx", "truncated_rx")]
        assert lost == [0, 0, 0, 0] and link["socket_errors_tx"] == 0, (role, link)
        serial = r["serial"][role]
        assert serial["baud"] == int(run) and serial["tx_overflow_frames"] == 0 and serial["pty_full_bytes"] == 0
        framing = serial["from_companion"]
        assert (framing["garbage_bytes"], framing["bad_crc"], framing["cut"]) == (0, 0, 0), (role, serial)
        assert serial["bytes_to_companion"] >= link["bytes_rx"] > 10_000  # the companion read what the line carried


@pytest.mark.sitl
@pytest.mark.slow
@flown_missions
@pytest.mark.timeout(240)
def test_the_telemetry_at_57600_stays_within_the_line(flown: dict[str, dict[str, Any]]) -> None:
    """In real time at 57,600 baud the companion received at most a quarter of what the line carries, and sent
    less."""
    for role, status in flown["57600"]["statuses"].items():
        wall = status["flight_wall_s"]
        assert wall > 8.0, role  # the 12 s mission flew in real time
        received = status["link"]["bytes_rx"] / wall
        sent = status["link"]["bytes_tx"] / wall
        print(f"{role}: {received:.0f} bytes/s from the vehicle, {sent:.0f} to it, of 5760 at 57600 baud")
        assert received < 0.25 * 5760 and sent < 0.25 * 5760


@pytest.mark.sitl
@pytest.mark.slow
@flown_missions
@pytest.mark.timeout(240)
def test_a_line_that_drops_bytes_is_survived(flown: dict[str, dict[str, Any]]) -> None:
    """One byte in 500 lost each way: frames are lost (counted by both framers and by the sequence numbers), none is
    taken wrong, and the mission still ends in success."""
    r = flown["lossy"]
    assert r["mission"]["success"] is True
    lost_frames = 0
    for role, status in r["statuses"].items():
        link, serial = status["link"], r["serial"][role]
        assert status["status"] == "success", role
        assert serial["bytes_lost_on_line"] > 0
        lost_frames += link["frames_lost_rx"]
        assert link["bad_data_rx"] + link["garbage_bytes_rx"] > 0, (role, link)
    assert lost_frames > 0
