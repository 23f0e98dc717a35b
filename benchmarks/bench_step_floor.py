"""The least CPU one lockstep step of a three-UAV SITL mission can cost in this architecture.

A lockstep step is a round over real UDP on 127.0.0.1 between four Python processes: the world sends each
companion its telemetry datagram, each companion filters it with filterpy's extended Kalman filter, asks its
policy for an action and sends one setpoint datagram back, and the world waits for all three before it steps.
This script measures the parts of that round no implementation of the architecture can leave out, each alone:

* ``transport``: the bare round, with no MAVLink, no physics and no filter: one world process sends three
  datagrams of the size a lean lockstep step sends (``--datagram-bytes``), three companion processes each
  answer with a setpoint-sized datagram, and the world waits (``select``) for the three answers. CPU of all four
  processes (user + system, from ``/proc``) per round.
* ``filter``: one companion's :class:`mavlink_bridge.estimation.state_filter.VehicleStateFilter` (the default
  constant-turn EKF, filterpy's ``ExtendedKalmanFilter``) predicting 0.1 s and taking one position/velocity fix,
  per step, on a turning track.
* ``policy``: one role's shipped actor (``--models``, the numpy forward pass the companion flies) on one
  observation, per decision; a decision holds for the actor's ``action_repeat`` steps.

``floor_ms`` = transport + 3 x filter + the policies' forward passes per step: a lower bound on the CPU of a step,
since the world's physics, truth log and MAVLink encoding, the companions' decoding and observation, and the
monitor all come on top. With missions per hour bound by CPU (two workers on two cores), a target of R times a
baseline that costs B ms of CPU per step allows B / R ms per step: ``--baseline-cpu-ms-per-step`` B (the
campaign benchmark's ``cpu_s_per_sim_s`` x 100 at dt = 0.1 s, start-up included), ``--target-ratio`` R, and
``--current-cpu-ms-per-step`` (this tree's, from the same campaign run) put the floor beside that budget.

    python benchmarks/bench_step_floor.py [--rounds 20000] [--models models/tssac] \\
        [--baseline-cpu-ms-per-step 3.15 --current-cpu-ms-per-step 1.41 --target-ratio 5] \\
        [--json benchmarks/results/step_floor.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import select
import socket
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from tssac_core.common.cli import command_description  # noqa: E402

COMPANIONS = 3
SETPOINT_BYTES = 53  # one signed SET_POSITION_TARGET_LOCAL_NED frame carries about this much
DT_S = 0.1

_ECHO = """
import socket, sys
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.bind(("127.0.0.1", 0))
print(sock.getsockname()[1], flush=True)
sock.settimeout(30.0)  # a benchmark that died without saying stop leaves no echo behind
reply = bytes({setpoint})
while True:
    try:
        data, world = sock.recvfrom(65536)
    except TimeoutError:
        break
    if data == b"stop":
        break
    sock.sendto(reply, world)
"""


def _cpu_s(pid: int) -> float:
    """User + system CPU seconds of a running process (the fly crew's reader of /proc)."""
    from mavlink_bridge.fly.crew import process_cpu_s

    used = process_cpu_s(pid)
    if used is None:
        raise RuntimeError(f"no CPU figure for process {pid} (it ended, or this is not Linux)")
    return used


def measure_transport(rounds: int, datagram_bytes: int) -> dict[str, float]:
    """CPU and wall time per bare lockstep round: three datagrams out, three answers back, a select to wait."""
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", _ECHO.format(setpoint=SETPOINT_BYTES)], stdout=subprocess.PIPE, text=True
        )
        for _ in range(COMPANIONS)
    ]
    try:
        assert all(p.stdout is not None for p in procs)
        ports = [int(p.stdout.readline()) for p in procs if p.stdout is not None]
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        sock.setblocking(False)
        payload = bytes(datagram_bytes)
        peers = [("127.0.0.1", port) for port in ports]
        for _ in range(200):  # warm up: every process scheduled and its socket buffers touched
            _round(sock, peers, payload)
        cpu0 = time.process_time() + sum(_cpu_s(p.pid) for p in procs)
        wall0 = time.perf_counter()
        for _ in range(rounds):
            _round(sock, peers, payload)
        wall = time.perf_counter() - wall0
        cpu = time.process_time() + sum(_cpu_s(p.pid) for p in procs) - cpu0
        for peer in peers:
            sock.sendto(b"stop", peer)
        sock.close()
    finally:
        for p in procs:
            try:
                p.wait(timeout=5)
            except subprocess.TimeoutExpired:
                p.kill()
    return {"cpu_us_per_round": 1e6 * cpu / rounds, "wall_us_per_round": 1e6 * wall / rounds}


def _round(sock: socket.socket, peers: Sequence[tuple[str, int]], payload: bytes) -> None:
    for peer in peers:
        sock.sendto(payload, peer)
    answers = 0
    while answers < len(peers):
        ready, _, _ = select.select([sock], [], [], 1.0)
        if not ready:
            raise RuntimeError("a companion stopped answering")
        while True:
            try:
                sock.recvfrom(65536)
            except BlockingIOError:
                break
            answers += 1


def measure_filter(steps: int) -> dict[str, float]:
    """CPU per step of the companion's default filter: predict 0.1 s, then one position/velocity fix."""
    from mavlink_bridge.estimation.state_filter import VehicleStateFilter

    rng = np.random.default_rng(0)
    speed, turn = 250.0, math.radians(3.0)
    filt = VehicleStateFilter()
    x = y = heading = 0.0
    fixes = []
    for k in range(steps + 1):
        heading += turn * DT_S
        x += speed * DT_S * math.cos(heading)
        y += speed * DT_S * math.sin(heading)
        noise = rng.normal(0.0, [10.0, 10.0, 1.0, 1.0])
        fixes.append(
            (
                k * DT_S,
                (x + noise[0], y + noise[1]),
                (speed * math.cos(heading) + noise[2], speed * math.sin(heading) + noise[3]),
            )
        )
    filt.update(*fixes[0])
    cpu0 = time.process_time()
    for t_s, pos, vel in fixes[1:]:
        filt.predict_to(t_s)
        filt.update(t_s, pos, vel)
    cpu = time.process_time() - cpu0
    return {"cpu_us_per_step": 1e6 * cpu / steps}


def measure_policy(models: Path, decisions: int) -> dict[str, dict[str, float]]:
    """CPU per decision of each role's shipped actor (numpy forward pass), on random observations, and the steps
    a decision holds."""
    from tssac_core.deploy.numpy_actor import NumpyPolicy, pilot_file
    from tssac_core.sim.scenario import Role

    out: dict[str, dict[str, float]] = {}
    rng = np.random.default_rng(0)
    for role in Role:
        policy = NumpyPolicy.load(pilot_file(models, role), role)
        observations = rng.uniform(-1.0, 1.0, size=(decisions, policy.obs_dim))
        for obs in observations[:100]:
            policy.act(obs)
        cpu0 = time.process_time()
        for obs in observations:
            policy.act(obs)
        out[role.value] = {
            "cpu_us_per_decision": 1e6 * (time.process_time() - cpu0) / decisions,
            "action_repeat": max(1, int(getattr(policy, "action_repeat", 1))),
        }
    return out


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    p.add_argument("--rounds", type=int, default=20_000, help="bare lockstep rounds (and filter steps) to time")
    p.add_argument("--datagram-bytes", type=int, default=150, help="the world's datagram per companion and step")
    p.add_argument("--models", type=Path, default=REPO / "models" / "tssac", help="the actors to time")
    p.add_argument(
        "--baseline-cpu-ms-per-step",
        type=float,
        default=None,
        help="CPU per step (ms, all four processes) of the baseline a speed-up target is measured against",
    )
    p.add_argument("--current-cpu-ms-per-step", type=float, default=None, help="CPU per step (ms) of this tree")
    p.add_argument("--target-ratio", type=float, default=5.0, help="the speed-up target over the baseline")
    p.add_argument("--json", type=Path, default=None)
    a = p.parse_args(argv)
    if a.rounds < 100:
        print("bench_step_floor: error: --rounds must be at least 100", file=sys.stderr)
        return 2
    transport = measure_transport(a.rounds, a.datagram_bytes)
    filt = measure_filter(a.rounds)
    policy = measure_policy(a.models, min(a.rounds, 20_000))
    policy_us_per_step = sum(p["cpu_us_per_decision"] / p["action_repeat"] for p in policy.values())
    floor_us = transport["cpu_us_per_round"] + COMPANIONS * filt["cpu_us_per_step"] + policy_us_per_step
    result: dict[str, Any] = {
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "load_1min": os.getloadavg()[0]},
        "transport": transport,
        "filter": filt,
        "policy": policy,
        "floor_ms_per_step": floor_us / 1000.0,
    }
    print(
        f"bare lockstep round (4 processes, 6 datagrams): {transport['cpu_us_per_round']:.0f} us CPU, "
        f"{transport['wall_us_per_round']:.0f} us wall"
    )
    print(f"filterpy EKF, predict + fix, per companion step: {filt['cpu_us_per_step']:.0f} us CPU")
    print(
        "policy forward, per decision: "
        + ", ".join(
            f"{r} {p['cpu_us_per_decision']:.0f} us every {p['action_repeat']:.0f} steps" for r, p in policy.items()
        )
    )
    print(
        f"floor: {floor_us / 1000:.3f} ms of CPU per lockstep step ({DT_S / (floor_us / 1e6) / 2:.0f}x real time "
        f"at best on 2 cores)"
    )
    if a.baseline_cpu_ms_per_step is not None:
        budget_ms = a.baseline_cpu_ms_per_step / a.target_ratio
        result["target"] = {
            "baseline_cpu_ms_per_step": a.baseline_cpu_ms_per_step,
            "ratio": a.target_ratio,
            "budget_ms_per_step": budget_ms,
            "floor_share_of_budget": floor_us / 1000.0 / budget_ms,
        }
        print(
            f"{a.target_ratio:g}x over {a.baseline_cpu_ms_per_step:.2f} ms allows {budget_ms:.3f} ms per step: "
            f"the floor alone is {100 * floor_us / 1000.0 / budget_ms:.0f}% of it"
        )
        if a.current_cpu_ms_per_step is not None:
            result["target"]["current_cpu_ms_per_step"] = a.current_cpu_ms_per_step
            print(
                f"this tree: {a.current_cpu_ms_per_step:.2f} ms per step, "
                f"{a.baseline_cpu_ms_per_step / a.current_cpu_ms_per_step:.2f}x the baseline"
            )
    if a.json is not None:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
