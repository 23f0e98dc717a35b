"""Attacks and faults against the SITL vehicles and a companion, over real UDP on 127.0.0.1: what gets through.

Each case plays one attack from issue 28 with real MAVLink bytes (pymavlink) against a world run in this
process (``WorldRunner`` in a thread, OS-assigned ports) and, for the companion cases, one
``python -m mavlink_bridge.companion`` subprocess, and prints one figure per case. Run it against any
tree (``PYTHONPATH=/path/to/tree python benchmarks/bench_attacks.py``) to compare before and after.

    python benchmarks/bench_attacks.py [--json FILE] [--cases poison_vehicle,...]

Cases (figures: lower is better unless said):

* ``poison_vehicle``: a signed client is connected; 3 HEARTBEATs signed with a wrong key on its stream
  (its link id, system and component ids), timestamp one year ahead, from another port; then 20 genuine
  commands: ``genuine_refused`` = commands without a COMMAND_ACK. Same with a forged COMMAND_LONG.
* ``telemetry_without_key``: signing on; one unsigned HEARTBEAT (and, separately, one wrongly signed
  HEARTBEAT) from a client without the key: bytes of telemetry it receives in the next 2 s.
* ``peer_flood``: signing off; 300 sockets each send one HEARTBEAT: clients the vehicle then serves and
  bytes it sends per second (to all of them).
* ``message_interval``: SET_MESSAGE_INTERVAL(ATTITUDE, 3e38 us): its result (2 = MAV_RESULT_DENIED is right, 0 =
ACCEPTED), then
  GET_MESSAGE_INTERVAL: whether MESSAGE_INTERVAL comes back and handler errors logged.
* ``unknown_id_header``: 5 datagrams of a garbage header claiming an unknown message id whose length covers a
  valid COMMAND_LONG behind it: commands acknowledged (5 is right).
* ``spoofed_mission_end``: signing off; a companion flies; one NAMED_VALUE_INT MSN_END = 1 with the
  vehicle's ids from another port: whether the companion ended (``ended_by_forgery``).
* ``poison_companion``: signing on; a companion flies; 3 HEARTBEATs with the vehicle's ids, a wrong key and a
  timestamp one year ahead, sent to the companion's port: the companion's genuine messages refused after.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import select
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import ardupilotmega as mavlink2  # noqa: E402

import tssac_core  # noqa: E402
from sim_vehicles.world_runner import WorldRunner  # noqa: E402
from tssac_core.common.cli import command_description
from tssac_core.sim.scenario import LinkModel, dump, load  # noqa: E402
from tssac_core.sim.sitl_config import SitlConfig  # noqa: E402

M = mavlink2
ROOT = Path(tssac_core.__file__).resolve().parents[1]
"""The tree under test (the one on PYTHONPATH), so the same script measures before and after."""
STRIKE = ROOT / "scenarios" / "strike.yaml"
KEY = bytes(range(32))
WRONG_KEY = bytes(32)
ONE_YEAR_10US = 365 * 24 * 3600 * 100_000
_EPOCH_2015 = 1420070400


def _now_10us() -> int:
    return int((time.time() - _EPOCH_2015) * 100_000)


class World:
    """A WorldRunner in a thread (real time x 5, exact GPS, ideal link)."""

    def __init__(self, key: bytes | None) -> None:
        scen = dataclasses.replace(load(STRIKE), link=LinkModel(gps_position_sigma_m=0.0, gps_velocity_sigma_m_s=0.0))
        self.scenario = scen
        self.runner = WorldRunner(SitlConfig(scenario=scen, base_port=0, speedup=5.0, signing_key=key, linger_s=0.0))
        self.thread = threading.Thread(target=self.runner.run, daemon=True)
        self.thread.start()
        self.port = self.runner.endpoints[0].port

    def close(self) -> None:
        self.runner.request_stop()
        self.thread.join(5.0)


class Peer:
    """A raw UDP socket with a pymavlink encoder/decoder (its own signing state)."""

    def __init__(
        self, port: int, key: bytes | None = None, sysid: int = 255, compid: int = 190, link_id: int = 1
    ) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.dest = ("127.0.0.1", port)
        self.mav = M.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.rx = M.MAVLink(None)
        self.rx.robust_parsing = True
        if key is not None:
            self.mav.signing.secret_key = key
            self.mav.signing.sign_outgoing = True
            self.mav.signing.link_id = link_id
            self.mav.signing.timestamp = _now_10us()
        self.bytes_rx = 0

    def send(self, msg: M.MAVLink_message, dest: tuple[str, int] | None = None) -> None:
        self.sock.sendto(msg.pack(self.mav), dest or self.dest)

    def recv(self, timeout_s: float) -> list[M.MAVLink_message]:
        out: list[M.MAVLink_message] = []
        deadline = time.monotonic() + timeout_s
        while (remaining := deadline - time.monotonic()) > 0:
            r, _, _ = select.select([self.sock], [], [], remaining)
            if not r:
                break
            data = self.sock.recv(65535)
            self.bytes_rx += len(data)
            out += [m for m in (self.rx.parse_buffer(data) or []) if m.get_type() != "BAD_DATA"]
        return out

    def heartbeat(self) -> None:
        self.send(self.mav.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0))

    def command(self, command: int, *params: float, timeout_s: float = 0.3) -> M.MAVLink_message | None:
        p = list(params) + [0.0] * (7 - len(params))
        self.send(self.mav.command_long_encode(1, 1, command, 0, *p))
        deadline = time.monotonic() + timeout_s
        while (remaining := deadline - time.monotonic()) > 0:
            for m in self.recv(min(remaining, 0.05)):
                if m.get_type() == "COMMAND_ACK" and m.command == command:
                    return m
        return None

    def close(self) -> None:
        self.sock.close()


def _forge(msg: M.MAVLink_message, sysid: int, compid: int, link_id: int, key: bytes, stamp_10us: int) -> bytes:
    """``msg`` from (sysid, compid), signed with ``key`` on ``link_id`` with timestamp ``stamp_10us``."""
    mav = M.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.signing.secret_key = key
    mav.signing.sign_outgoing = True
    mav.signing.link_id = link_id
    mav.signing.timestamp = stamp_10us
    return msg.pack(mav)


def case_poison_vehicle() -> dict[str, Any]:
    out: dict[str, Any] = {}
    for kind in ("heartbeat", "command_long"):
        world = World(KEY)
        good, evil = Peer(world.port, KEY, link_id=1), Peer(world.port)
        try:
            good.heartbeat()
            good.recv(0.5)
            forged = (
                M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
                if kind == "heartbeat"
                else M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            )
            for i in range(3):
                evil.sock.sendto(_forge(forged, 255, 190, 1, WRONG_KEY, _now_10us() + ONE_YEAR_10US + i), evil.dest)
            time.sleep(0.2)
            acks = sum(
                good.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION) is not None for _ in range(20)
            )
            out[f"{kind}_genuine_refused_of_20"] = 20 - acks
        finally:
            good.close()
            evil.close()
            world.close()
    return out


def case_telemetry_without_key() -> dict[str, Any]:
    out: dict[str, Any] = {}
    world = World(KEY)
    try:
        for kind, key in (("unsigned", None), ("wrong_key", WRONG_KEY)):
            p = Peer(world.port, key)
            p.heartbeat()
            p.recv(2.0)
            out[f"{kind}_heartbeat_bytes_in_2s"] = p.bytes_rx
            p.close()
    finally:
        world.close()
    return out


def case_peer_flood(n: int = 300) -> dict[str, Any]:
    world = World(None)
    peers = [Peer(world.port) for _ in range(n)]
    try:
        for p in peers:
            p.heartbeat()
        time.sleep(0.5)
        endpoint = world.runner.links[0].endpoint
        b0, t0 = endpoint.tx.bytes, time.monotonic()
        time.sleep(2.0)
        rate = (endpoint.tx.bytes - b0) / (time.monotonic() - t0)
        return {"fake_peers": n, "clients_served": len(endpoint.peers), "tx_bytes_per_s": round(rate)}
    finally:
        for p in peers:
            p.close()
        world.close()


def case_message_interval() -> dict[str, Any]:
    world = World(None)
    p = Peer(world.port)
    try:
        p.heartbeat()
        p.recv(0.3)
        ack = p.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, 3e38)
        p.send(
            p.mav.command_long_encode(
                1, 1, M.MAV_CMD_GET_MESSAGE_INTERVAL, 0, M.MAVLINK_MSG_ID_ATTITUDE, 0, 0, 0, 0, 0, 0
            )
        )
        got = [m for m in p.recv(0.5) if m.get_type() in ("MESSAGE_INTERVAL", "COMMAND_ACK")]
        v = world.runner.vehicles[0]
        return {
            "set_3e38_result": None if ack is None else ack.result,
            "get_answered": any(m.get_type() == "MESSAGE_INTERVAL" for m in got),
            "get_ack_result": next((m.result for m in got if m.get_type() == "COMMAND_ACK"), None),
            "handler_errors": v.counters.handler_errors,
        }
    finally:
        p.close()
        world.close()


def case_unknown_id_header() -> dict[str, Any]:
    world = World(None)
    p = Peer(world.port)
    try:
        p.heartbeat()
        p.recv(0.3)
        acks = 0
        for _ in range(5):
            valid = p.mav.command_long_encode(
                1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, M.MAVLINK_MSG_ID_HOME_POSITION, 0, 0, 0, 0, 0, 0
            ).pack(p.mav)
            garbage = bytes([0xFD, len(valid) - 2, 0, 0, 0, 1, 1, 0xEE, 0xEE, 0xEE])  # claims 10 + len - 2 + 2 bytes
            p.sock.sendto(garbage + valid, p.dest)
            deadline = time.monotonic() + 0.3
            while time.monotonic() < deadline:
                if any(m.get_type() == "COMMAND_ACK" for m in p.recv(0.05)):
                    acks += 1
                    break
        return {"acknowledged_of_5": acks}
    finally:
        p.close()
        world.close()


def _companion(world: World, key_file: Path | None, tmp: Path) -> tuple[subprocess.Popen[bytes], Path]:
    layout = tmp / "layout.yaml"
    dump(dataclasses.replace(world.scenario, layout=world.runner.layout, random=None), layout)
    status = tmp / "status.json"
    cmd = [
        sys.executable,
        "-m",
        "mavlink_bridge.companion",
        "--connect",
        f"udpout:127.0.0.1:{world.port}",
        "--role",
        "decoy",
        "--pilot",
        "guidance",
        "--scenario",
        str(layout),
        "--status-json",
        str(status),
        "--log-level",
        "warning",
    ]
    if key_file is not None:
        cmd += ["--signing-key", str(key_file)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
    return proc, status


def _wait_flying(world: World, timeout_s: float = 90.0) -> tuple[str, int] | None:
    v, endpoint = world.runner.vehicles[0], world.runner.links[0].endpoint
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if v.armed and int(v.mode) == 15 and endpoint.peers:
            time.sleep(0.5)
            return next(iter(endpoint.peers))
        time.sleep(0.05)
    return None


def _stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.terminate()
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def case_spoofed_mission_end() -> dict[str, Any]:
    world = World(None)
    with tempfile.TemporaryDirectory() as d:
        proc, status = _companion(world, None, Path(d))
        try:
            addr = _wait_flying(world)
            if addr is None:
                return {"error": "companion did not engage"}
            evil = M.MAVLink(None, srcSystem=1, srcComponent=1)
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.sendto(evil.named_value_int_encode(10_000_000, b"MSN_END", 1).pack(evil), addr)
            sock.close()
            try:
                proc.wait(3.0)
            except subprocess.TimeoutExpired:
                pass
            ended = proc.poll() is not None
            _stop(proc)
            end = json.loads(status.read_text()).get("status") if status.exists() else None
            return {"ended_by_forgery": ended, "status": end}
        finally:
            _stop(proc)
            world.close()


def case_poison_companion() -> dict[str, Any]:
    world = World(KEY)
    with tempfile.TemporaryDirectory() as d:
        key_file = Path(d) / "key.bin"
        key_file.write_bytes(KEY)
        proc, status = _companion(world, key_file, Path(d))
        try:
            addr = _wait_flying(world)
            if addr is None:
                return {"error": "companion did not engage"}
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            hb = M.MAVLink_heartbeat_message(M.MAV_TYPE_FIXED_WING, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0, 3)
            for i in range(3):
                sock.sendto(_forge(hb, 1, 1, 0, WRONG_KEY, _now_10us() + ONE_YEAR_10US + i), addr)
            sock.close()
            time.sleep(3.0)
            v = world.runner.vehicles[0]
            failsafe = v.failsafe
            _stop(proc)
            counters = json.loads(status.read_text()).get("link", {}) if status.exists() else {}
            return {
                "vehicle_failsafe_3s_after": failsafe,
                "companion_signature_rejected": counters.get("signature_rejected"),
                "companion_foreign_rx": counters.get("foreign_rx"),
            }
        finally:
            _stop(proc)
            world.close()


CASES: dict[str, Callable[[], dict[str, Any]]] = {
    "poison_vehicle": case_poison_vehicle,
    "telemetry_without_key": case_telemetry_without_key,
    "peer_flood": case_peer_flood,
    "message_interval": case_message_interval,
    "unknown_id_header": case_unknown_id_header,
    "spoofed_mission_end": case_spoofed_mission_end,
    "poison_companion": case_poison_companion,
}


def main() -> int:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    p.add_argument("--json", type=Path, help="write the figures here")
    p.add_argument("--cases", default=",".join(CASES), help="comma-separated case names (default: all)")
    args = p.parse_args()
    results: dict[str, Any] = {}
    for name in args.cases.split(","):
        t0 = time.monotonic()
        try:
            results[name] = CASES[name]()
        except Exception as exc:  # a case that breaks is a figure too
            results[name] = {"error": repr(exc)}
        print(f"{name}: {results[name]}  ({time.monotonic() - t0:.1f} s)", flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
