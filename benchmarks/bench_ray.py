"""Ray against this machine's own ways, side by side: the grid's executor, sharded evaluation, parallel SITL
missions, a two-node Ray on one machine, and the paper's full-budget grid on K nodes.

    python benchmarks/bench_ray.py [--parts executor,idle,evaluate,evaluate_warm,fly,two_nodes,estimate] [--json FILE]

- ``executor``: the same two training jobs (a two-job grid, each job one thread), both at once, with the
  local executor and with ``--executor ray`` (a Ray of 2 CPUs started inside the command), alternately;
  the command's wall time each (Ray's start and stop included) and Ray's overhead as a share of it (JSON key
  ``executor_<steps>_steps``: one entry per job length measured).
- ``idle``: the CPU seconds Ray's own processes (raylet, GCS, agents, the waiting generator tasks, the driver) take
  in 60 s while two tasks wait as the executor's tasks wait on their training processes: the part of the
  executor's overhead that grows with the jobs' length. CPU seconds, so a busy machine changes them little.
- ``evaluate``: ``tssac_core.evaluate`` on ``--layouts`` layouts with the shipped models, serial and
  ``--workers 2``, alternately: missions per second of the whole command (Ray's start included) and the
  same with ``--address`` to a Ray already running; the JSON of both must be equal.
- ``evaluate_warm``: the flight alone (no process or Ray start-up), serial against 2 warm Ray workers, in one
  process (:func:`bench_evaluate_warm`).
- ``fly``: ``mavlink_bridge.fly`` on ``--missions`` SITL missions of scenarios/random.yaml with the
  shipped models, serial and ``--workers 2``: missions per second, and the figures must be equal. Lockstep by
  default (each mission as fast as the CPUs go); ``--speedup X``: the world in real time times X, each mission
  waiting on the clock as a real SITL does (JSON key ``fly_realtime_<X>x``; the figures then vary with timing).
- ``two_nodes``: ``ray start --head`` plus a second ``ray start --address`` on this machine (1 CPU each,
  their own temporary directory, stopped at the end), then the two-job grid with ``--address``: each job
  must run on its own node, and the trained teams must be those of the local executor.
- ``estimate``: the measured wall time of every run of results/runs (by its train.log) at the grid's
  budget, doubled for the paper's 50 epochs per role, scheduled in the grid's order on K nodes of C CPUs
  (a job per CPU, each to the first free one): the expected wall time of the full-budget grid.

Prints the figures and the machine's load average beside them, and writes them as JSON (into ``--json``: the
parts not run keep the figures the file had).
"""

from __future__ import annotations

import argparse
import heapq
import json
import os
import platform
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.output import add_json_option  # noqa: E402
from tssac_core.common.cli import command_description  # noqa: E402
from tssac_core.experiments.evaluations import team_digest  # noqa: E402
from tssac_core.experiments.grid import load_grid  # noqa: E402
from tssac_core.train.wall_time import training_wall_s  # noqa: E402

PYTHON = sys.executable
PAPER_EPOCHS = 50


def load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"{one:.1f} / {five:.1f} / {fifteen:.1f}"


def timed(argv: list[str], env: dict[str, str] | None = None) -> tuple[float, subprocess.CompletedProcess[str]]:
    t0 = time.perf_counter()
    done = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({done.returncode}): {done.stderr.strip().splitlines()[-1:]}")
    return wall, done


def write_grid(directory: Path, steps: int) -> Path:
    """The smoke grid with ``steps`` learner decisions per epoch: two jobs long enough to time."""
    text = (
        (ROOT / "experiments" / "smoke.yaml")
        .read_text()
        .replace("  steps_per_epoch: 20\n", f"  steps_per_epoch: {steps}\n", 1)
    )
    path = directory / "bench_grid.yaml"
    path.write_text(text)
    return path


def train_only(grid: Path, results: Path, *extra: str) -> float:
    """Wall seconds of training the grid's jobs (``--only '*'``; the report is made by a later invocation)."""
    code = (
        "import sys, time; from tssac_core.experiments.cli import parse_args, train;"
        "from tssac_core.experiments.grid import load_grid;"
        "from tssac_core.parallel.ray_cluster import RayTarget; a = parse_args(sys.argv[1:]); t = time.perf_counter();"
        "ls = train(load_grid(a.grid), a.results, a.jobs, report=lambda l: print(l, flush=True), executor=a.executor,"
        " ray_target=RayTarget(a.address, a.cpus)); print('WALL', time.perf_counter() - t);"
        "sys.exit(any(x.returncode != 0 for x in ls))"
    )
    wall, done = timed([PYTHON, "-c", code, "--grid", str(grid), "--results", str(results), "--jobs", "2", *extra])
    print("   ", " | ".join(line for line in done.stdout.splitlines() if line.startswith(("started", "Ray:"))))
    return wall


def digests(results: Path, grid: Path) -> dict[str, str]:
    return {job.name: team_digest(job.out) for job in load_grid(grid).jobs(results)}


def bench_executor(work: Path, steps: int, rounds: int) -> dict[str, Any]:
    grid = write_grid(work, steps)
    walls: dict[str, list[float]] = {"local": [], "ray": []}
    teams = {}
    for r in range(rounds):
        for executor in ("local", "ray") if r % 2 == 0 else ("ray", "local"):
            results = work / f"exec-{executor}-{r}"
            extra = ["--executor", "ray", "--cpus", "2"] if executor == "ray" else []
            print(f"  round {r + 1}: {executor} (load {load()})", flush=True)
            walls[executor].append(train_only(grid, results, *extra))
            teams[executor] = digests(results, grid)
            print(f"    {walls[executor][-1]:.1f} s", flush=True)
    local, ray = sum(walls["local"]) / rounds, sum(walls["ray"]) / rounds
    return {
        "jobs": 2,
        "steps_per_epoch": steps,
        "epochs_per_role": 1,
        "threads_per_job": 1,
        "rounds": rounds,
        "local_wall_s": walls["local"],
        "ray_wall_s": walls["ray"],
        "overhead_share": (ray - local) / ray,
        "same_teams": teams["local"] == teams["ray"],
        "load_average_after": load(),
    }


def process_cpu_s() -> dict[int, tuple[str, float]]:
    """CPU seconds (user + system) so far of this process and of every Ray process (a worker, ``ray::...``, or a
    program of Ray's package), by pid: (what it is, seconds). Linux /proc."""
    tick = os.sysconf("SC_CLK_TCK")
    out = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            argv = (entry / "cmdline").read_bytes().split(b"\0")
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:  # ended meanwhile
            continue
        words = [w.decode(errors="replace") for w in argv if w]
        ray_words = [w for w in words if w.startswith("ray::") or "/ray/" in w]  # Ray's workers, its programs
        if int(entry.name) == os.getpid() or ray_words:
            what = Path(ray_words[0]).name if ray_words else "driver"
            out[int(entry.name)] = (what, (int(fields[11]) + int(fields[12])) / tick)
    return out


def waiting_task(seconds: float, wake_s: float) -> Iterator[float]:
    """A Ray generator task that reports its start and waits as the grid's tasks wait on their training process:
    waking every ``wake_s``."""
    yield 0.0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        time.sleep(wake_s)
    yield seconds


def bench_idle(seconds: float) -> dict[str, Any]:
    """Ray's own CPU while two grid tasks wait on their training (a local Ray of 2 CPUs, generator tasks and a driver
    waking as the executor's do): what Ray takes from jobs that fill the machine."""
    from tssac_core.parallel.ray_cluster import RayTarget, ray_session
    from tssac_core.train.jobs.ray_executor import DRIVER_WAKE_S, TASK_WAKE_S

    with ray_session(RayTarget(cpus=2)) as ray:
        task = ray.remote(max_retries=0)(waiting_task)
        refs = [task.remote(seconds + 30.0, TASK_WAKE_S) for _ in range(2)]
        for ref in refs:  # started
            ray.get(next(ref))
        time.sleep(10.0)  # past the start-up
        before = process_cpu_s()
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds:
            ray.wait(refs, num_returns=len(refs), timeout=DRIVER_WAKE_S)
        after = process_cpu_s()
        wall = time.monotonic() - t0
        for ref in refs:
            ray.cancel(ref, force=True)
    by_kind: dict[str, float] = {}
    for pid, (what, cpu) in after.items():
        by_kind[what] = by_kind.get(what, 0.0) + cpu - before.get(pid, (what, 0.0))[1]
    total = sum(by_kind.values())
    return {
        "seconds": wall,
        "cpu_s": total,
        "share_of_one_core": total / wall,
        "share_of_machine": total / wall / (os.cpu_count() or 1),
        "cpu_s_by_process": dict(sorted(((k, round(v, 2)) for k, v in by_kind.items()), key=lambda kv: -kv[1])),
        "load_average_after": load(),
    }


def bench_evaluate(work: Path, layouts: int) -> dict[str, Any]:
    base = [
        PYTHON,
        "-m",
        "tssac_core.evaluate",
        "--models",
        "models/tssac",
        "--scenario",
        "scenarios/random.yaml",
        "--episodes",
        str(layouts),
        "--seed",
        "880001",
        "--no-progress",
    ]
    out: dict[str, Any] = {"layouts": layouts}
    runs = {"serial": [], "workers2": [], "workers2_running_ray": []}
    head = start_head(work / "ray-eval", cpus=2)
    try:
        address = head[1]
        for name, extra in (
            ("serial", []),
            ("workers2", ["--workers", "2"]),
            ("workers2_running_ray", ["--workers", "2", "--address", address]),
            ("serial", []),
        ):
            print(f"  {name} (load {load()})", flush=True)
            wall, _ = timed([*base, *extra, "--json", str(work / f"eval-{name}.json")])
            runs[name].append(wall)
            print(f"    {wall:.1f} s, {layouts / wall:.1f} missions/s", flush=True)
    finally:
        stop(head[0])
    serial = sum(runs["serial"]) / len(runs["serial"])
    same = (
        json.loads((work / "eval-serial.json").read_text())
        == json.loads((work / "eval-workers2.json").read_text())
        == json.loads((work / "eval-workers2_running_ray.json").read_text())
    )
    out.update(
        {
            "wall_s": runs,
            "missions_per_s": {k: layouts / (sum(v) / len(v)) for k, v in runs.items()},
            "speedup": {k: serial / (sum(v) / len(v)) for k, v in runs.items() if k != "serial"},
            "same_json": same,
            "load_average_after": load(),
        }
    )
    return out


def bench_evaluate_warm(layouts: int, rounds: int) -> dict[str, Any]:
    """The flight alone, in this process: ``fly_missions`` of ``layouts`` missions against
    ``fly_missions_sharded`` over 2 workers of a Ray started once and warmed up (its workers have imported
    torch and flown a mission), alternately: the missions per second a long-lived driver gets (a notebook, or
    a cluster user evaluating many teams), without the start-up every fresh command pays."""
    import torch

    from tssac_core.evaluate import load_pilots
    from tssac_core.parallel.mission_shards import fly_missions_sharded
    from tssac_core.parallel.ray_cluster import OBJECT_STORE_BYTES, RayTarget, import_ray
    from tssac_core.sim.missions import fly_missions
    from tssac_core.sim.scenario import load as load_scenario

    torch.set_num_threads(1)
    scenario = load_scenario(ROOT / "scenarios" / "random.yaml")
    pilots = load_pilots(ROOT / "models" / "tssac")
    indices = list(range(layouts))
    ray = import_ray()
    ray.init(num_cpus=2, object_store_memory=OBJECT_STORE_BYTES, include_dashboard=False)
    walls: dict[str, list[float]] = {"serial": [], "workers2": []}
    success: dict[str, Any] = {}
    try:
        target = RayTarget()
        fly_missions_sharded(scenario, pilots, [0, 1], 880001, 2, target)  # warm-up: both workers import and fly
        for r in range(rounds):
            for name in ("serial", "workers2") if r % 2 == 0 else ("workers2", "serial"):
                print(f"  {name} (load {load()})", flush=True)
                t0 = time.perf_counter()
                if name == "serial":
                    result = fly_missions(scenario, pilots, layouts, 880001, indices=indices)
                else:
                    result = fly_missions_sharded(scenario, pilots, indices, 880001, 2, target)
                walls[name].append(time.perf_counter() - t0)
                print(f"    {walls[name][-1]:.1f} s, {layouts / walls[name][-1]:.1f} missions/s", flush=True)
                success[name] = result.success.copy()
    finally:
        ray.shutdown()
    mean = {k: sum(v) / len(v) for k, v in walls.items()}
    return {
        "layouts": layouts,
        "rounds": rounds,
        "wall_s": walls,
        "missions_per_s": {k: layouts / v for k, v in mean.items()},
        "speedup": mean["serial"] / mean["workers2"],
        "same_success": bool((success["serial"] == success["workers2"]).all()),
        "load_average_after": load(),
    }


def bench_fly(work: Path, missions: int, speedup: float | None = None) -> dict[str, Any]:
    """Serial against ``--workers 2 --executor ray``: lockstep (``speedup`` None: each mission as fast as the CPUs
    allow, the same missions both ways) or real time times ``speedup`` (each mission paced by the clock, so its
    figures may vary with timing: ``same_missions`` is then a finding, not a requirement)."""
    clock = ["--speedup", f"{speedup:g}"] if speedup is not None else []
    base = [
        PYTHON,
        "-m",
        "mavlink_bridge.fly",
        "--scenario",
        "scenarios/random.yaml",
        "--models",
        "models/tssac",
        "--episodes",
        str(missions),
        "--seed",
        "880001",
        "--no-progress",
        *clock,
    ]
    runs: dict[str, float] = {}
    for name, extra in (("serial", []), ("workers2", ["--workers", "2", "--executor", "ray"])):
        print(f"  {name} (load {load()})", flush=True)
        runs[name], _ = timed([*base, *extra, "--json", str(work / f"fly-{name}.json")])
        print(f"    {runs[name]:.1f} s, {missions / runs[name]:.3f} missions/s", flush=True)
    keys = ("success", "end", "steps", "sim_time_s", "cost", "task_done")
    serial, parallel = (json.loads((work / f"fly-{n}.json").read_text()) for n in ("serial", "workers2"))
    same = [{k: m.get(k) for k in keys} for m in serial["missions"]] == [
        {k: m.get(k) for k in keys} for m in parallel["missions"]
    ]
    return {
        "missions": missions,
        "clock": "lockstep" if speedup is None else f"real time x{speedup:g}",
        "wall_s": runs,
        "missions_per_s": {k: missions / v for k, v in runs.items()},
        "speedup": runs["serial"] / runs["workers2"],
        "same_missions": same,
        "success_rate": {"serial": serial["success_rate"], "workers2": parallel["success_rate"]},
        "mean_cost": {"serial": serial["mean_cost"], "workers2": parallel["mean_cost"]},
        "mean_sim_time_s": statistics.fmean(m["sim_time_s"] for m in serial["missions"] if m.get("sim_time_s")),
        "load_average_after": load(),
    }


def start_head(temp: Path, cpus: int) -> tuple[list[subprocess.Popen[bytes]], str]:
    """``ray start --head --block`` in its own temporary directory; returns the process and its address."""
    temp.mkdir(parents=True, exist_ok=True)
    port = free_port()
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0"}
    head = subprocess.Popen(
        [
            shutil.which("ray") or "ray",
            "start",
            "--head",
            "--block",
            f"--port={port}",
            f"--num-cpus={cpus}",
            "--include-dashboard=false",
            f"--temp-dir={temp}",
            "--object-store-memory=134217728",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
        start_new_session=True,
    )
    address = f"127.0.0.1:{port}"
    wait_for_nodes(address, 1)
    return [head], address


def add_node(procs: list[subprocess.Popen[bytes]], address: str, temp: Path, cpus: int) -> None:
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0"}
    procs.append(
        subprocess.Popen(
            [
                shutil.which("ray") or "ray",
                "start",
                "--block",
                f"--address={address}",
                f"--num-cpus={cpus}",
                "--object-store-memory=134217728",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
            start_new_session=True,
        )
    )
    wait_for_nodes(address, 2)


def wait_for_nodes(address: str, count: int, timeout_s: float = 300.0) -> None:
    code = (
        f"import ray, sys; ray.init(address='{address}', logging_level='ERROR');"
        f"sys.exit(0 if sum(n['Alive'] for n in ray.nodes()) >= {count} else 1)"
    )
    deadline = time.monotonic() + timeout_s
    while (
        subprocess.run(
            [PYTHON, "-c", code], capture_output=True, env={**os.environ, "RAY_USAGE_STATS_ENABLED": "0"}
        ).returncode
        != 0
    ):
        if time.monotonic() > deadline:
            raise SystemExit(f"the Ray at {address} did not show {count} node(s) in {timeout_s:.0f} s")
        time.sleep(2)


def stop(procs: list[subprocess.Popen[bytes]]) -> None:
    """Stop the ``ray start --block`` processes (each stops its node's Ray processes), the added node first."""
    for proc in reversed(procs):
        proc.terminate()
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, 9)
            proc.wait()


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def bench_two_nodes(work: Path, steps: int) -> dict[str, Any]:
    grid = write_grid(work, steps)
    procs, address = start_head(work / "ray-two", cpus=1)
    try:
        add_node(procs, address, work / "ray-two", cpus=1)
        results = work / "two-nodes"
        code = (
            "import sys; from tssac_core.experiments.cli import parse_args, train;"
            "from tssac_core.experiments.grid import load_grid;"
            "from tssac_core.parallel.ray_cluster import RayTarget; a = parse_args(sys.argv[1:]);"
            "ls = train(load_grid(a.grid), a.results, None, report=lambda l: print(l, flush=True), executor='ray',"
            " ray_target=RayTarget(a.address)); sys.exit(any(x.returncode != 0 for x in ls))"
        )
        print(f"  two nodes at {address} (load {load()})", flush=True)
        wall, done = timed(
            [
                PYTHON,
                "-c",
                code,
                "--grid",
                str(grid),
                "--results",
                str(results),
                "--executor",
                "ray",
                "--address",
                address,
            ]
        )
    finally:
        stop(procs)
    nodes = re.findall(r"^started \S+: on \S+ \(node ([0-9a-f]+)\)", done.stdout, re.M)
    local = work / "exec-local-0"
    same = digests(results, grid) == digests(local, grid) if local.is_dir() else None
    print("   ", " | ".join(line for line in done.stdout.splitlines() if line.startswith(("started", "Ray:"))))
    return {
        "wall_s": wall,
        "nodes_used": sorted(set(nodes)),
        "jobs_on_distinct_nodes": len(set(nodes)) == 2,
        "same_teams_as_local": same,
        "load_average_after": load(),
    }


def grid_estimate(nodes: tuple[int, ...], cpus_per_node: int) -> dict[str, Any]:
    """The grid's runs (results/runs) at the full budget on K nodes: module docstring."""
    grid = load_grid(ROOT / "experiments" / "paper.yaml")
    results = ROOT / "results"
    jobs = [*grid.jobs(results), *grid.transfer_jobs(results)]
    measured = {job.name: training_wall_s(job.out) for job in jobs}
    by_entry: dict[str, list[float]] = {}
    for job in jobs:
        if measured[job.name]:
            by_entry.setdefault(f"{job.role or ''}{job.entry.name}", []).append(measured[job.name])
    scale = PAPER_EPOCHS / grid.train.epochs
    minutes = []
    for job in jobs:
        key = f"{job.role or ''}{job.entry.name}"
        seconds = measured[job.name] or sorted(by_entry[key])[len(by_entry[key]) // 2]
        # the transfer runs stop at 90% task success: their length does not grow with the budget
        minutes.append(seconds / 60 * (1.0 if job.role else scale))
    out: dict[str, Any] = {
        "runs": len(jobs),
        "budget_scale": scale,
        "cpus_per_node": cpus_per_node,
        "total_core_hours": sum(minutes) / 60,
        "longest_run_min": max(minutes),
        "hours_on": {},
    }
    for k in nodes:
        free = [0.0] * (k * cpus_per_node)
        heapq.heapify(free)
        end = 0.0
        for m in minutes:  # the grid's order, each job to the first free CPU (what the executor does)
            start = heapq.heappop(free)
            end = max(end, start + m)
            heapq.heappush(free, start + m)
        out["hours_on"][str(k)] = end / 60
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    p.add_argument("--parts", default="executor,idle,evaluate,evaluate_warm,fly,two_nodes,estimate")
    p.add_argument(
        "--steps", type=int, default=600, help="learner decisions per epoch of the two timed jobs (default 600)"
    )
    p.add_argument("--rounds", type=int, default=2, help="alternations of local and ray (default 2)")
    p.add_argument("--layouts", type=int, default=1000)
    p.add_argument("--missions", type=int, default=50)
    p.add_argument(
        "--speedup",
        type=float,
        default=None,
        help="fly: the SITL world in real time times X (default: lockstep); JSON key fly_realtime_<X>x",
    )
    add_json_option(p, "ray")
    a = p.parse_args()
    parts = a.parts.split(",")
    started = time.strftime("%Y-%m-%d %H:%M")
    out: dict[str, Any] = {
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "load_average_before": load()}
    }
    with tempfile.TemporaryDirectory(prefix="bench-ray-") as tmp:
        work = Path(tmp)
        if "executor" in parts:
            print(
                f"executor: two jobs of {a.steps} decisions per epoch, local against ray, {a.rounds} rounds", flush=True
            )
            out[f"executor_{a.steps}_steps"] = r = bench_executor(work, a.steps, a.rounds)
            print(
                f"  local {r['local_wall_s']} s, ray {r['ray_wall_s']} s: "
                f"Ray's overhead {r['overhead_share']:.1%} of its wall time; "
                f"same teams {r['same_teams']}",
                flush=True,
            )
        if "idle" in parts:
            print("idle: Ray's own CPU while two tasks wait on their training, 60 s", flush=True)
            out["idle"] = r = bench_idle(60.0)
            print(
                f"  {r['cpu_s']:.2f} CPU s in {r['seconds']:.0f} s: {r['share_of_one_core']:.1%} of one core, "
                f"{r['share_of_machine']:.1%} of the machine; {r['cpu_s_by_process']}",
                flush=True,
            )
        if "two_nodes" in parts:
            print("two nodes on this machine", flush=True)
            out["two_nodes"] = r = bench_two_nodes(work, a.steps)
            print(
                f"  {r['wall_s']:.1f} s, nodes {r['nodes_used']}, same teams as local: {r['same_teams_as_local']}",
                flush=True,
            )
        if "evaluate" in parts:
            print(f"evaluate: {a.layouts} layouts, serial against --workers 2", flush=True)
            out["evaluate"] = r = bench_evaluate(work, a.layouts)
            print(
                f"  missions/s {r['missions_per_s']}, speed-up {r['speedup']}, same JSON {r['same_json']}", flush=True
            )
        if "evaluate_warm" in parts:
            print(f"evaluate_warm: {a.layouts} layouts' flight, serial against 2 warm Ray workers", flush=True)
            out["evaluate_warm"] = r = bench_evaluate_warm(a.layouts, a.rounds)
            print(
                f"  missions/s {r['missions_per_s']}, speed-up {r['speedup']:.2f}, same {r['same_success']}", flush=True
            )
        if "fly" in parts:
            clock = "lockstep" if a.speedup is None else f"real time x{a.speedup:g}"
            print(f"fly: {a.missions} SITL missions ({clock}), serial against --workers 2", flush=True)
            key = "fly" if a.speedup is None else f"fly_realtime_{a.speedup:g}x"
            out[key] = r = bench_fly(work, a.missions, a.speedup)
            print(
                f"  missions/s {r['missions_per_s']}, speed-up {r['speedup']:.2f}, same missions {r['same_missions']}",
                flush=True,
            )
    if "estimate" in parts:
        out["estimate"] = r = grid_estimate((1, 2, 4, 8, 16), 2)
        print(
            f"the full-budget grid: {r['runs']} runs, {r['total_core_hours']:.0f} core-hours, "
            f"longest run {r['longest_run_min']:.0f} min; "
            + ", ".join(f"{k} node(s) of 2 CPUs: {h:.1f} h" for k, h in r["hours_on"].items()),
            flush=True,
        )
    out["machine"]["load_average_after"] = load()
    for key, part in out.items():  # each part says which command measured it, and when
        if key != "machine" and isinstance(part, dict):
            part.update(command=" ".join(["python", "benchmarks/bench_ray.py", *sys.argv[1:]]), date=started)
    # The parts not run this time keep their figures from the file (each part records its own load average).
    earlier = json.loads(a.json.read_text()) if a.json.is_file() else {}
    a.json.parent.mkdir(parents=True, exist_ok=True)
    a.json.write_text(json.dumps({**earlier, **out}, indent=1))
    print(f"wrote {a.json}")


if __name__ == "__main__":
    main()
