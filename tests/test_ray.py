"""Ray as the engine: the grid's jobs as tasks that survive their workers' deaths and stop on Ctrl-C, and
missions sharded over workers with the serial run's results. One local Ray of 2 CPUs serves the module
(started once: Ray's start-up costs seconds); the commands run in this process and use it."""

from __future__ import annotations

import csv
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from sitl_helpers import cmdline, running
from tiny_training import tiny_args

from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.common.cli import run
from tssac_core.evaluate import main as evaluate_main
from tssac_core.experiments.cli import train
from tssac_core.experiments.grid import load_grid
from tssac_core.parallel.mission_shards import fly_missions_sharded, shard
from tssac_core.parallel.ray_cluster import OBJECT_STORE_BYTES, RAY_ENVIRONMENT, RayTarget, import_ray
from tssac_core.parallel.ray_map import TaskFailed, map_on_ray
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.pilots import GUIDANCE
from tssac_core.sim.scenario import load as load_scenario
from tssac_core.train.jobs.runner import LOG_NAME, Status, job_state
from tssac_core.train.wall_time import Ended, read_invocations

ROOT = Path(__file__).resolve().parent.parent
SMOKE = ROOT / "experiments" / "smoke.yaml"
RAY = RayTarget()
# The first test waits for the Ray start: seconds (minutes on a loaded machine). One Ray at a time on this machine:
# the tests that start one run in the same xdist worker.
pytestmark = [pytest.mark.timeout(900), pytest.mark.xdist_group("ray")]


@pytest.fixture(scope="module")
def local_ray():
    """A local Ray of 2 CPUs for the module, shut down after it."""
    ray = import_ray()
    ray.init(num_cpus=2, object_store_memory=OBJECT_STORE_BYTES, include_dashboard=False, logging_level="WARNING")
    yield ray
    ray.shutdown()


@pytest.fixture(autouse=True)
def at_root(monkeypatch):
    monkeypatch.chdir(ROOT)


def two_epoch_grid(tmp_path: Path, algos: str = "  - tssac\n  - sac_lag\n", epochs: int = 2) -> Path:
    """The smoke grid with two epochs per role (a run stopped after its first decoy epoch has work left)."""
    text = SMOKE.read_text().replace("  - tssac\n  - sac_lag\n", algos, 1)
    text = text.replace("  epochs: 1\n", f"  epochs: {epochs}\n", 1)
    path = tmp_path / "grid.yaml"
    path.write_text(text)
    return path


def wait_for(condition, timeout_s: float = 600.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError("timed out")
        time.sleep(0.05)


def epochs(run: Path) -> list[tuple[str, str]]:
    with (run / "metrics.csv").open() as fh:
        return [(r["role"], r["epoch"]) for r in csv.DictReader(fh)]


def worker_pids(run: Path) -> list[int]:
    return [int(p) for p in re.findall(r"^=== ray worker pid (\d+)", (run / LOG_NAME).read_text(), re.M)]


def test_shards_cover_every_index_once():
    assert shard(range(10), 3) == [[0, 1, 2], [3, 4, 5], [6, 7, 8, 9]]
    assert shard([7, 9], 5) == [[7], [9]]
    assert [i for piece in shard(range(1001), 4) for i in piece] == list(range(1001))


def test_sharded_evaluation_equals_the_serial_one(local_ray, tmp_path):
    """The same JSON, figure for figure, from one batched world or three shards on two workers; and, mission by
    mission, the same outcomes in the same order."""
    args = ["--controller", "guidance", "--scenario", "scenarios/short-random.yaml", "--episodes", "9", "--seed", "31"]
    assert evaluate_main([*args, "--no-progress", "--json", str(tmp_path / "serial.json")]) == 0
    assert evaluate_main([*args, "--no-progress", "--workers", "3", "--json", str(tmp_path / "sharded.json")]) == 0
    serial, sharded = (json.loads((tmp_path / f"{name}.json").read_text()) for name in ("serial", "sharded"))
    assert sharded == serial

    scenario = load_scenario(ROOT / "scenarios" / "short-random.yaml")
    one = fly_missions(scenario, [GUIDANCE] * 3, 5, 31, indices=[2, 3, 5, 7, 8])
    pieces = fly_missions_sharded(scenario, [GUIDANCE] * 3, [2, 3, 5, 7, 8], 31, 2, RAY)
    assert pieces.indices == one.indices and pieces.seeds == one.seeds == [33, 34, 36, 38, 39]
    for name in ("success", "cost", "returns", "task_done", "time_s", "out_of_area"):
        assert np.array_equal(getattr(pieces, name), getattr(one, name)), name
    assert len(set(one.returns[:, 0].tolist())) == 5  # five different missions, not one five times
    shielded = fly_missions(scenario, [GUIDANCE] * 3, 5, 31, indices=[2, 3, 5, 7, 8], shield=ShieldConfig())
    pieces = fly_missions_sharded(scenario, [GUIDANCE] * 3, [2, 3, 5, 7, 8], 31, 2, RAY, shield=ShieldConfig())
    assert (
        pieces.record(scenario.cost_limit).to_json() == shielded.record(scenario.cost_limit).to_json()
    )  # the monitor's counts too
    assert pieces.monitor is not None and np.array_equal(pieces.monitor.flown_steps, shielded.monitor.flown_steps)


@pytest.mark.sitl
def test_fly_on_workers_flies_the_serial_missions(local_ray, tmp_path):
    """``fly --workers 2 --executor ray``: each SITL mission a Ray task on its own ports; the rows, in index order,
    those of the serial run (lockstep: the same steps, end, cost), from processes of their own."""
    from mavlink_bridge.fly.cli import main as fly_main

    args = ["--scenario", "scenarios/short-random.yaml", "--models", "models/tssac", "--episodes", "2", "--seed", "41"]
    assert fly_main([*args, "--no-progress", "--json", str(tmp_path / "serial.json")]) == 0
    argv = [*args, "--no-progress", "--workers", "2", "--executor", "ray", "--json", str(tmp_path / "workers.json")]
    assert fly_main(argv) == 0
    serial, workers = (json.loads((tmp_path / f"{name}.json").read_text()) for name in ("serial", "workers"))
    keys = ("index", "seed", "success", "end", "steps", "sim_time_s", "cost", "task_done")
    rows = [[{k: m[k] for k in keys} for m in run["missions"]] for run in (serial, workers)]
    assert rows[0] == rows[1] and [r["seed"] for r in rows[0]] == [41, 42]
    assert rows[0][0]["steps"] != rows[0][1]["steps"]  # two different missions, not one twice
    assert workers["success_rate"] == serial["success_rate"] and workers["mean_cost"] == serial["mean_cost"]
    pids = [set(m["pids"].values()) for m in workers["missions"]]
    assert not pids[0] & pids[1] and not {p for m in serial["missions"] for p in m["pids"].values()} & pids[0]


def _descendants(pid: int) -> set[int]:
    """Every live process below ``pid`` (children, their children, ...), from /proc."""
    parents: dict[int, int] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parents[int(stat.parent.name)] = int(fields[1])
    found, frontier = set(), {pid}
    while frontier:
        frontier = {child for child, parent in parents.items() if parent in frontier} - found
        found |= frontier
    return found


@pytest.mark.slow
@pytest.mark.sitl
def test_sigterm_stops_fly_on_workers_and_leaves_no_process_behind(tmp_path):
    """SIGTERM to ``fly --workers 2 --executor ray`` (its own Ray) ends it as Ctrl-C does: exit 130, the JSON of the
    missions finished so far, and every process it started gone, its crews' and Ray's (``ray.init`` had put Ray's
    own SIGTERM handler, ``sys.exit``, in place of fly's: no JSON, and Ray's node agent orphaned)."""
    out = tmp_path / "fly.json"
    args = ["--scenario", "scenarios/random.yaml", "--pilot", "guidance", "--episodes", "40", "--seed", "41"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "mavlink_bridge.fly", *args, "--workers", "2", "--executor", "ray", "--no-progress"]
        + ["--json", str(out)],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 240
        started: set[int] = set()
        worlds: list[int] = []
        while time.monotonic() < deadline and proc.poll() is None:  # until both workers fly a mission
            started = _descendants(proc.pid)
            worlds = [p for p in started if b"sim_vehicles" in cmdline(p)]
            if len(worlds) == 2:
                break
            time.sleep(0.2)
        assert len(worlds) == 2, "fly --workers 2 never had two worlds flying"
        time.sleep(2.0)
        started = _descendants(proc.pid)
        assert any(b"ray" in cmdline(p) for p in started)  # Ray's own processes are among them
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    assert proc.returncode == 130, err.decode()[-2000:]
    results = json.loads(out.read_text())
    assert results["interrupted"] is True and results["episodes_requested"] == 40 and results["episodes"] < 40
    assert all(m["success"] for m in results["missions"])
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and [p for p in started if running(p)]:
        time.sleep(0.5)
    left = {p: cmdline(p)[:120] for p in started if running(p)}
    assert not left, left


def counting(item: int):
    """A map_on_ray task: yields 1..item as progress, returns item * 10; item 13 raises."""
    if item == 13:
        raise ValueError("item 13 is unlucky")
    yield from range(1, item + 1)
    return item * 10


def dying_once(folder: str):
    """A map_on_ray task whose first attempt reports progress three times, waits until the driver has read them
    (its file ``seen``), then its worker process dies; the next attempt reports nothing and returns its pid."""
    first, seen = Path(folder) / "first", Path(folder) / "seen"
    if not first.exists():
        first.touch()
        yield from (1, 2, 3)
        deadline = time.monotonic() + 120
        while not seen.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        os._exit(1)
    return os.getpid()


@pytest.fixture
def tasks_by_value():
    """This module's task functions travel to the workers by value (the workers cannot import tests/)."""
    from ray import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    yield
    cloudpickle.unregister_pickle_by_value(sys.modules[__name__])


def test_map_on_ray_streams_progress_and_keeps_the_items_order(local_ray, tasks_by_value):
    events: list[int] = []
    done: list[tuple[int, int]] = []
    results = map_on_ray(
        counting, [3, 1, 2], 2, RAY, on_result=lambda i, r: done.append((i, r)), on_event=events.append
    )
    assert results == [30, 10, 20]
    assert sorted(done) == [(0, 30), (1, 10), (2, 20)]
    assert sorted(events) == [1, 1, 1, 2, 2, 3]  # every yield of every task, once
    assert map_on_ray(abs, [-2, 5], 2, RAY) == [2, 5]  # a plain function: its return value, no progress


def test_map_on_ray_names_the_item_whose_task_raised(local_ray, tasks_by_value):
    with pytest.raises(TaskFailed) as failed:
        map_on_ray(counting, [1, 13, 2], 2, RAY)
    assert failed.value.index == 1
    assert "item 13 is unlucky" in str(failed.value) and "\n" not in str(failed.value)


class _Billion:
    """A billion items, each made when read; reading beyond the first hundred fails the test (a copy of the items, a
    list of their results, fill the memory before the first task runs)."""

    def __init__(self) -> None:
        self.read: list[int] = []

    def __len__(self) -> int:
        return 10**9

    def __getitem__(self, index: int) -> int:
        assert index < 100, f"item {index} read before its turn"
        self.read.append(index)
        return index


def test_map_on_ray_reads_each_item_when_it_submits_it(local_ray, tasks_by_value):
    """``fly --workers 2 --episodes 100000000`` on Ray: the items are read one by one as they are submitted, and
    without ``collect`` no result is kept."""

    class Enough(Exception):
        pass

    items, done = _Billion(), []

    def on_result(index: int, result: int) -> None:
        done.append(result)
        if len(done) == 5:
            raise Enough()

    with pytest.raises(Enough):
        map_on_ray(abs, items, 2, RAY, on_result=on_result, collect=False)
    assert len(done) == 5 and set(done) <= set(range(7)) and len(items.read) <= 7


def test_map_on_ray_runs_an_item_again_when_its_worker_dies(local_ray, tasks_by_value, tmp_path):
    """Submitted again by the driver: the retry's result arrives though it yields fewer times than the dead
    attempt did (Ray's own retry would drop it as already seen)."""
    events: list[int] = []

    def on_event(event: int) -> None:
        events.append(event)
        if len(events) == 3:
            (tmp_path / "seen").touch()

    [pid] = map_on_ray(dying_once, [str(tmp_path)], 1, RAY, on_event=on_event)
    assert (tmp_path / "first").exists() and isinstance(pid, int)
    assert events == [1, 2, 3]


@pytest.mark.slow
def test_a_job_whose_worker_is_killed_resumes(local_ray, tmp_path):
    """SIGKILL to the Ray worker mid-job: its training process dies with it, Ray runs the task again, and the
    run resumes from its last finished epoch (no epoch trained twice)."""
    grid = load_grid(two_epoch_grid(tmp_path, algos="  - tssac\n"))
    results = tmp_path / "results"
    run = results / "runs" / "tssac-seed0"
    killed: list[int] = []

    def kill_the_worker() -> None:
        wait_for(lambda: (run / "resume" / "decoy.pt").is_file() and worker_pids(run))
        pid = worker_pids(run)[0]
        os.kill(pid, signal.SIGKILL)
        killed.append(pid)

    killer = threading.Thread(target=kill_the_worker, daemon=True)
    killer.start()
    lines: list[str] = []
    launches = train(grid, results, 1, report=lines.append, executor="ray", ray_target=RAY)
    killer.join(timeout=1)
    assert killed, "the job finished before its worker could be killed"
    assert len(launches) == 1 and launches[0].returncode == 0, lines
    assert job_state(grid.jobs(results)[0]).status is Status.FINISHED
    assert any(line.startswith("started tssac-seed0 again after its worker died (resume)") for line in lines), lines
    assert epochs(run) == [(role, e) for role in ("decoy", "detect", "strike") for e in ("1", "2")]
    log = (run / LOG_NAME).read_text()
    headers = re.findall(r"runner: (.*)", log)
    assert len(headers) == 2 and "--resume" not in headers[0] and "--resume" in headers[1], log
    assert worker_pids(run)[0] == killed[0] and worker_pids(run)[1] != killed[0]


def test_ctrl_c_stops_every_job_and_leaves_each_resumable(local_ray, tmp_path):
    """SIGINT to the driver while two jobs train: both training processes are stopped, each run's log says so,
    and both runs are partial (the next invocation resumes them). The jobs have far more epochs than they get
    to train, so the interrupt finds them running however late a loaded machine reports their start."""
    grid = load_grid(two_epoch_grid(tmp_path, epochs=200))
    results = tmp_path / "results"
    runs = [job.out for job in grid.jobs(results)]
    lines: list[str] = []

    def interrupt() -> None:
        wait_for(
            lambda: (
                sum(line.startswith("started ") for line in lines) == 2
                and all((r / "config.json").is_file() for r in runs)
            )
        )
        os.kill(os.getpid(), signal.SIGINT)

    # Python's KeyboardInterrupt handler, whatever this process inherited: a test run started in the background
    # (`cmd &` in a script) inherits SIGINT ignored, and Python then installs no handler (see test_fly).
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    threading.Thread(target=interrupt, daemon=True).start()
    try:
        with pytest.raises(KeyboardInterrupt):
            train(grid, results, 2, report=lines.append, executor="ray", ray_target=RAY)
    finally:
        signal.signal(signal.SIGINT, previous)
    pids = [int(re.search(r"training pid (\d+)", line).group(1)) for line in lines if line.startswith("started ")]
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    for run_dir in runs:
        assert re.search(r"runner: stopped after \d+ s", (run_dir / LOG_NAME).read_text()), run_dir
        assert [i.ended for i in read_invocations(run_dir)] == [Ended.STOPPED], run_dir  # its wall time counts
    assert [job_state(job).status for job in grid.jobs(results)] == [Status.PARTIAL, Status.PARTIAL], lines
    assert sorted(line.split()[1] for line in lines if line.startswith("stopping ")) == [
        "sac_lag-seed0;",
        "tssac-seed0;",
    ]


@pytest.mark.parametrize(
    "command, argv, message",
    [
        ("experiments", ["--grid", "experiments/smoke.yaml", "--address", "auto"], "--address is for --executor ray"),
        ("experiments", ["--grid", "experiments/smoke.yaml", "--cpus", "2"], "--cpus is for --executor ray"),
        (
            "experiments",
            ["--grid", "experiments/smoke.yaml", "--executor", "ray", "--address", "auto", "--cpus", "2"],
            "--cpus sizes the Ray started here",
        ),
        ("train", ["--seed", "0", "--out", "unused", "--executor", "ray"], "--executor ray runs the jobs of --seeds"),
        ("train", ["--seeds", "0,1", "--out", "unused", "--address", "auto"], "--address is for --executor ray"),
        ("evaluate", ["--workers", "0"], "--workers must be positive"),
        (
            "fly",
            ["--scenario", "scenarios/strike.yaml", "--pilot", "guidance", "--workers", "0"],
            "--workers must be positive",
        ),
    ],
)
def test_ray_flags_in_the_wrong_place_are_one_line(command, argv, message, capsys):
    """Checked before anything starts (no Ray, no run directory): one line on stderr, exit 2."""
    from mavlink_bridge.fly.cli import main as fly_main
    from tssac_core.experiments.cli import main as experiments_main
    from tssac_core.train.cli import main as train_main

    if command == "fly":
        code = fly_main(argv)
    else:
        code = run({"experiments": experiments_main, "train": train_main, "evaluate": evaluate_main}[command], argv)
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and message in err, err
    assert not (ROOT / "unused").exists()


@pytest.mark.slow
def test_train_seeds_run_as_ray_tasks(local_ray, tmp_path, capsys):
    """``train --seeds 0,1 --executor ray``: both seeds' runs, as the local executor writes them."""
    from tssac_core.train.cli import main as train_main

    tiny = tiny_args()
    out = tmp_path / "seeds"
    assert train_main([*tiny, "--seeds", "0,1", "--out", str(out), "--executor", "ray"]) == 0
    assert json.loads((out / "seeds.json").read_text()) == {"seeds": [0, 1]}
    for seed in (0, 1):
        run_dir = out / f"seed{seed}"
        assert (run_dir / "decoy.pt").is_file() and json.loads((run_dir / "config.json").read_text())["seed"] == seed
        assert worker_pids(run_dir), "not run by a Ray worker"
    assert "trained seeds 0, 1 with sac_lag" in capsys.readouterr().out


QUIET_SESSION = """
import sys, time
from tssac_core.parallel.ray_cluster import RayTarget, ray_session
with ray_session(RayTarget(cpus=1)) as ray:
    print(ray.get(ray.remote(lambda: "task ran").remote()))
    time.sleep(float(sys.argv[1]))
"""


@pytest.mark.slow
def test_a_local_ray_says_nothing_on_the_console():
    """Ray's own lines stay off the command's stderr: no "Set ray log level" line from its start, no FutureWarning,
    none of its C++ core's errors (the missing metrics agent's comes some 30 s after the start, longer than this session
    lives: RAY_BACKEND_LOG_LEVEL, which this session runs under as every command's does, is what keeps it off)."""
    done = subprocess.run(
        [sys.executable, "-c", QUIET_SESSION, "5"], capture_output=True, text=True, timeout=180, cwd=ROOT
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "task ran"
    assert done.stderr.strip() == ""
    assert "RAY_BACKEND_LOG_LEVEL" in RAY_ENVIRONMENT


def test_without_ray_a_command_that_needs_it_says_so_in_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # what an install without the [ray] extra imports
    code = run(evaluate_main, ["--controller", "guidance", "--episodes", "4", "--workers", "2", "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err == ["error: Ray is not installed: pip install -e '.[ray]' (in '.[dev]' too)"]
