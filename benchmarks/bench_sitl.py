"""Lockstep speed of the SITL: world steps per second with three vehicles and a minimal client.

Starts ``python -m sim_vehicles --lockstep`` as a subprocess (OS-assigned ports on 127.0.0.1), arms
all three vehicles in GUIDED from one client process, then plays the lockstep protocol as fast as it
can: per step, wait for every vehicle's SYSTEM_TIME tick, then send each one a
SET_POSITION_TARGET_LOCAL_NED stamped with that tick's time_boot_ms. The client only walks frame
headers and decodes just the ticks, so the figure is the SITL's.

    python benchmarks/bench_sitl.py [--steps 3000] [--warmup 100] [--json benchmarks/results/sitl.json]

Prints the steps per second (and the SITL process's CPU time per step) and writes them as JSON.
"""

from __future__ import annotations

import argparse
import os
import platform
import select
import socket
import subprocess
import sys
import time
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # for benchmarks.output
from benchmarks.output import add_json_option, write_figures  # noqa: E402
from mavlink_bridge.fly.crew import process_cpu_s
from tssac_core.common.cli import command_description

ROOT = Path(__file__).resolve().parents[1]
SETPOINT_MASK = 1087
CLIENT_SYSID, CLIENT_COMPID = 255, 191


class BenchError(RuntimeError):
    pass


class MinimalLink:
    """One UDP socket to one vehicle, a pymavlink encoder, and a header-peeking receiver."""

    def __init__(self, host: str, port: int) -> None:
        self.addr = (host, port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.mav = mavlink2.MAVLink(None, CLIENT_SYSID, CLIENT_COMPID)
        self.latest_ms = 0
        self.ended = False

    def send(self, msg: mavlink2.MAVLink_message) -> None:
        self.sock.sendto(msg.pack(self.mav), self.addr)
        self.mav.seq = (self.mav.seq + 1) % 256

    def drain(self) -> list[mavlink2.MAVLink_message]:
        """Read what is waiting; decode only SYSTEM_TIME, COMMAND_ACK and NAMED_VALUE_INT frames.

        A datagram may hold several frames (the vehicles pack a step's telemetry into one): the frames are
        walked by their headers (MAVLink 2: 10 header bytes, payload, 2 CRC bytes, 13 if signed).
        """
        out = []
        while True:
            try:
                data = self.sock.recv(65535)
            except BlockingIOError:
                return out
            i = 0
            while i + 12 <= len(data) and data[i] == mavlink2.PROTOCOL_MARKER_V2:
                size = 12 + data[i + 1] + (13 if data[i + 2] & mavlink2.MAVLINK_IFLAG_SIGNED else 0)
                frame, i = data[i : i + size], i + size
                msg_id = frame[7] | (frame[8] << 8) | (frame[9] << 16)
                if msg_id == mavlink2.MAVLINK_MSG_ID_SYSTEM_TIME:
                    msg = self.mav.decode(bytearray(frame))
                    self.latest_ms = max(self.latest_ms, msg.time_boot_ms)
                elif msg_id in (mavlink2.MAVLINK_MSG_ID_COMMAND_ACK, mavlink2.MAVLINK_MSG_ID_NAMED_VALUE_INT):
                    msg = self.mav.decode(bytearray(frame))
                    if msg.get_type() == "NAMED_VALUE_INT" and msg.name == "MSN_END":
                        self.ended = True
                    out.append(msg)

    def command(self, command: int, *params: float, timeout_s: float = 2.0) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            self.send(self.mav.command_long_encode(0, 0, command, 0, *p))
            retry = time.monotonic() + 0.3
            while time.monotonic() < min(retry, deadline):
                select.select([self.sock], [], [], 0.05)
                for m in self.drain():
                    if m.get_type() == "COMMAND_ACK" and m.command == command:
                        if m.result != mavlink2.MAV_RESULT_ACCEPTED:
                            raise BenchError(f"command {command} refused by {self.addr}: result {m.result}")
                        return
        raise BenchError(f"no COMMAND_ACK for command {command} from {self.addr}")

    def setpoint(self, stamp_ms: int) -> None:
        self.send(
            self.mav.set_position_target_local_ned_encode(
                stamp_ms, 0, 0, mavlink2.MAV_FRAME_BODY_FRD, SETPOINT_MASK, 0, 0, 0, 0, 0, 0, 0.0, 0, 0, 0, 0.0
            )
        )


def start_sitl(scenario: Path, timeout_s: float) -> tuple[subprocess.Popen[bytes], list[tuple[str, int]]]:
    cmd = [
        sys.executable,
        "-m",
        "sim_vehicles",
        "--scenario",
        str(scenario),
        "--lockstep",
        "--base-port",
        "0",
        "--linger-s",
        "0",
    ]
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT, env=env)
    assert proc.stdout is not None
    buf = b""
    deadline = time.monotonic() + timeout_s
    while b"\nready" not in b"\n" + buf:
        if time.monotonic() > deadline or proc.poll() is not None:
            proc.kill()
            raise BenchError(f"SITL did not start: {proc.stderr.read().decode() if proc.stderr else ''}{buf.decode()}")
        if select.select([proc.stdout], [], [], 0.2)[0]:
            buf += os.read(proc.stdout.fileno(), 4096)
    endpoints = []
    for line in buf.decode().splitlines()[:3]:
        host, port = line.split()[2].split(":", 1)[1].rsplit(":", 1)
        endpoints.append((host, int(port)))
    return proc, endpoints


def run(steps: int, warmup: int, scenario: Path, timeout_s: float) -> dict[str, object]:
    proc, endpoints = start_sitl(scenario, timeout_s=30.0)
    links = [MinimalLink(h, p) for h, p in endpoints]
    try:
        for link in links:
            link.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1)
            link.command(mavlink2.MAV_CMD_DO_SET_MODE, mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 15)
        socks = [link.sock for link in links]
        deadline = time.monotonic() + timeout_s
        done, t0, cpu0 = 0, 0.0, None
        current_ms = 0
        for k in range(warmup + steps):
            if k == warmup:
                t0, cpu0 = time.perf_counter(), process_cpu_s(proc.pid)
            for link in links:
                link.setpoint(current_ms)
            # wait for every vehicle's tick of the next step
            while not all(link.latest_ms > current_ms or link.ended for link in links):
                if time.monotonic() > deadline:
                    raise BenchError(f"timed out after {k} steps")
                select.select(socks, [], [], 0.1)
                for link in links:
                    link.drain()
            if any(link.ended for link in links):
                break
            current_ms = min(link.latest_ms for link in links)
            done = k + 1 - warmup
        wall = time.perf_counter() - t0
        cpu1 = process_cpu_s(proc.pid)
    finally:
        for link in links:
            link.sock.close()
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)
    if done <= 0:
        raise BenchError("the mission ended during the warm-up")
    dt_s = 0.1
    sitl_cpu = None if cpu0 is None or cpu1 is None else cpu1 - cpu0
    return {
        "benchmark": "sitl_lockstep",
        "scenario": scenario.name,
        "vehicles": 3,
        "steps": done,
        "wall_s": round(wall, 3),
        "steps_per_s": round(done / wall, 1),
        "realtime_factor": round(done * dt_s / wall, 1),
        "sitl_cpu_ms_per_step": None if sitl_cpu is None else round(1000.0 * sitl_cpu / done, 3),
        "python": platform.python_version(),
        "machine": f"{platform.system()} {platform.machine()}, {os.cpu_count()} cpus",
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    p.add_argument(
        "--steps", type=int, default=3000, help="measured steps (default 3000; the strike scenario caps at 4000)"
    )
    p.add_argument("--warmup", type=int, default=100, help="steps before the clock starts (default 100)")
    p.add_argument("--scenario", type=Path, default=ROOT / "scenarios" / "strike.yaml")
    p.add_argument("--timeout-s", type=float, default=300.0, help="give up after this long")
    add_json_option(p, "sitl")
    args = p.parse_args(argv)
    try:
        result = run(args.steps, args.warmup, args.scenario, args.timeout_s)
    except BenchError as exc:
        print(f"bench_sitl: error: {exc}", file=sys.stderr)
        return 1
    print(
        f"lockstep, 3 vehicles: {result['steps_per_s']} world steps/s ({result['realtime_factor']}x real time), "
        f"SITL CPU {result['sitl_cpu_ms_per_step']} ms/step over {result['steps']} steps"
    )
    write_figures(args.json, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
