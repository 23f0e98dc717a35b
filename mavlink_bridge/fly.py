"""``python -m mavlink_bridge.fly``: fly whole three-UAV missions over MAVLink against SITL vehicles.

Examples::

    python -m mavlink_bridge.fly --scenario scenarios/strike.yaml --pilot guidance --json out.json --plot mission.png
    python -m mavlink_bridge.fly --scenario scenarios/random.yaml --models models/tssac --episodes 10 --seed 3 --tlog tlogs/
    python -m mavlink_bridge.fly --scenario layout.yaml --pilot guidance --connect udpout:127.0.0.1:14560 udpout:127.0.0.1:14570 udpout:127.0.0.1:14580

For each mission: the layout is the scenario's fixed one, or a random one drawn with
``sample_layout(scenario, numpy.random.default_rng(seed + mission index))``; it is written as a
fixed-layout scenario file that the SITL world and the companions both read. The world starts as
its own process (``python -m sim_vehicles``, OS-assigned ports, lockstep by default) and one
companion process per UAV (``python -m mavlink_bridge.companion``) connects to its vehicle. When the
world ends (target hit, a UAV leaving the area, or the episode cap) the outcome is read from the
world's truth log: success, hazard cost per UAV, mission time in simulated seconds.

Every child runs in its own process group; Ctrl-C, SIGTERM, a crash of any child or a mission
timeout stops them all (SIGTERM, then SIGKILL after a grace period) and the results of the missions
that finished are still written. With ``--connect`` the companions fly vehicles that are already
running (one connection string per role, decoy detect strike); there is then no truth log, so the
outcome comes from the companions (the vehicles' HIT / MSN_END notices) and the cost is unknown.

Exit status: 0 when every mission was flown (whatever its outcome), 2 on bad input (one line), 1
when a child crashed or a mission timed out, 130 when interrupted.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import os
import resource
import select
import signal
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import Any, NoReturn, Optional, Sequence

import numpy as np
from tqdm import tqdm

from mavlink_bridge.companion import read_signing_key
from mavlink_bridge.link import parse_connection
from mavlink_bridge.mission_log import MissionRecord, TruthLogError, read_mission
from mavlink_bridge.processes import Child, ChildProcesses
from tssac_core.cli import EXIT_BAD_INPUT, EXIT_INTERRUPTED, UsageError, write_json
from tssac_core.errors import CheckpointError
from tssac_core.numpy_actor import load_actor, pilot_file
from tssac_core.scenario import ROLES, Layout, Scenario, ScenarioError, dump, load, sample_layout

_log = logging.getLogger("mavlink_bridge.fly")

PROG = "python -m mavlink_bridge.fly"
REPO = Path(__file__).resolve().parent.parent
DEFAULT_MODELS = REPO / "models" / "tssac"
GUIDANCE = "guidance"
EXIT_FAILED = 1
LOCKSTEP_SETPOINT_TIMEOUT_S = 5.0
"""Under lockstep the vehicles' setpoint failsafe counts wall seconds at the step barrier: 5 s keeps a
companion that a loaded machine paused for a moment in the loop (failsafes are still counted)."""


class ChildFailed(Exception):
    """A child process crashed or a mission hung; ``str()`` is one line."""


@dataclass(frozen=True)
class FlyConfig:
    scenario_path: Path
    scenario: Scenario
    models: Optional[Path]
    """None = the guidance controller."""
    episodes: int
    seed: int
    lockstep: bool
    speedup: float
    json_path: Optional[Path]
    tlog_dir: Optional[Path]
    plot_path: Optional[Path]
    signing_key_path: Optional[Path]
    connect: Optional[tuple[str, str, str]]
    logs_dir: Optional[Path]
    mission_timeout_s: float
    startup_timeout_s: float
    progress: bool
    lean_telemetry: bool = False


# -------------------------------------------------------------------------------- arguments


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise UsageError(f"{message} (see --help)")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog=PROG, description="Fly whole missions over MAVLink: a SITL world plus one companion process per UAV.")
    p.add_argument("--scenario", required=True, type=Path, metavar="FILE", help="scenario file (scenarios/strike.yaml, scenarios/random.yaml)")
    who = p.add_mutually_exclusive_group()
    who.add_argument("--models", type=Path, metavar="DIR", help=f"directory with decoy.pt, detect.pt, strike.pt (default {DEFAULT_MODELS.relative_to(REPO)})")
    who.add_argument("--pilot", choices=[GUIDANCE], help="fly every UAV with the rule-based guidance controller")
    p.add_argument("--episodes", type=int, default=1, metavar="N", help="missions to fly (default 1)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="mission i uses seed S + i for its random layout and sensor noise (default 0)")
    clock = p.add_mutually_exclusive_group()
    clock.add_argument("--lockstep", action="store_true",
                       help="step the world once per round of setpoints (the default; with --connect: the running world is in lockstep)")
    clock.add_argument("--speedup", type=float, metavar="X", help="run the world in real time times X instead of lockstep")
    p.add_argument("--json", type=Path, metavar="FILE", help="write the results here (also the finished missions when interrupted)")
    p.add_argument("--tlog", type=Path, metavar="DIR", help="write DIR/mission-NNN/<role>.tlog (each companion's MAVLink traffic)")
    p.add_argument("--plot", type=Path, metavar="FILE", help="draw the trajectories (FILE, or FILE-NNN.ext per mission when there are several)")
    p.add_argument("--signing-key", type=Path, metavar="FILE", help="MAVLink 2 signing key (32 raw bytes or 64 hex characters) for the world and the companions")
    p.add_argument("--connect", nargs=3, metavar=("DECOY", "DETECT", "STRIKE"), help="fly running vehicles at these connection strings instead of starting a world")
    p.add_argument("--logs", type=Path, metavar="DIR", help="keep each mission's scenario, truth log and process logs here (default: a temporary directory)")
    p.add_argument("--lean-telemetry", action="store_true",
                   help="companions stop the vehicle streams they do not use (GLOBAL_POSITION_INT, ATTITUDE, VFR_HUD): faster, leaner tlogs")
    p.add_argument("--mission-timeout-s", type=float, default=900.0, metavar="S", help="wall seconds a mission may take (default 900)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def config_from_args(argv: Sequence[str] | None) -> FlyConfig:
    a = build_parser().parse_args(argv)
    if a.episodes <= 0:
        raise UsageError(f"--episodes must be positive, got {a.episodes}")
    if a.speedup is not None and not (math.isfinite(a.speedup) and a.speedup > 0):
        raise UsageError(f"--speedup must be a positive number, got {a.speedup}")
    if not (math.isfinite(a.mission_timeout_s) and a.mission_timeout_s > 0):
        raise UsageError("--mission-timeout-s must be positive")
    scenario = load(a.scenario)
    models: Optional[Path] = None
    if a.pilot is None:
        models = (a.models if a.models is not None else DEFAULT_MODELS).resolve()
        check_models(models)
    if a.signing_key is not None:
        read_signing_key(a.signing_key)
    connect: Optional[tuple[str, str, str]] = None
    if a.connect is not None:
        for text in a.connect:
            try:
                parse_connection(text)
            except ValueError as exc:
                raise UsageError(str(exc)) from None
        if a.episodes != 1:
            raise UsageError("--connect flies the running vehicles once: --episodes must be 1")
        if scenario.layout is None:
            raise UsageError(f"{a.scenario}: with --connect the scenario must have the fixed layout the vehicles fly "
                             "(python -m sim_vehicles --layout-out FILE writes it)")
        if a.plot is not None:
            raise UsageError("--plot draws from the world's truth log, which fly has only for the worlds it starts (not with --connect)")
        connect = (a.connect[0], a.connect[1], a.connect[2])
    return FlyConfig(
        scenario_path=a.scenario.resolve(),
        scenario=scenario,
        models=models,
        episodes=a.episodes,
        seed=a.seed,
        # A world fly starts runs in lockstep unless --speedup; vehicles it did not start are taken to run in
        # real time unless --lockstep says otherwise (a companion must not extrapolate a lockstep clock).
        lockstep=a.lockstep or (a.speedup is None and connect is None),
        speedup=1.0 if a.speedup is None else float(a.speedup),
        json_path=a.json,
        tlog_dir=a.tlog.resolve() if a.tlog is not None else None,
        plot_path=a.plot,
        signing_key_path=a.signing_key.resolve() if a.signing_key is not None else None,
        connect=connect,
        logs_dir=a.logs.resolve() if a.logs is not None else None,
        mission_timeout_s=a.mission_timeout_s,
        startup_timeout_s=60.0,
        progress=not a.no_progress,
        lean_telemetry=a.lean_telemetry,
    )


def make_signing_key(directory: Path) -> Path:
    """A fresh random 32-byte MAVLink 2 signing key, readable by its owner only."""
    path = directory / "signing.key"
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as fh:
        fh.write(os.urandom(32))
    return path


def check_models(models: Path) -> None:
    """The three roles' actors load (CheckpointError otherwise), with a hint when they are missing."""
    hint = "fly with --pilot guidance, or train with python -m tssac_core.train --out DIR and pass --models DIR"
    if not models.is_dir():
        raise UsageError(f"{models}: models directory not found ({hint})")
    try:
        for role in ROLES:
            load_actor(pilot_file(models, role), role)
    except CheckpointError as exc:
        raise UsageError(f"{exc} ({hint})") from None


def mission_layout(scenario: Scenario, seed: int, index: int) -> Layout:
    """The layout of mission ``index``: the fixed one, or ``sample_layout`` with ``default_rng(seed + index)``."""
    return sample_layout(scenario, np.random.default_rng(seed + index))


# --------------------------------------------------------------------------------- missions


def _child_env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    env.setdefault("OMP_NUM_THREADS", "1")  # small networks: threads only fight each other
    return env


def _children_cpu_s() -> float:
    """User + system CPU seconds of every child reaped so far (the mission's processes, once it is over)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _tail(path: Optional[Path], lines: int = 1) -> str:
    if path is None or not path.exists():
        return ""
    text = [ln for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    return " | ".join(text[-lines:])


class MissionRunner:
    """Starts and watches the processes of each mission (see the module docstring)."""

    def __init__(self, cfg: FlyConfig, children: ChildProcesses, work_dir: Path) -> None:
        self.cfg = cfg
        self.children = children
        self.work_dir = work_dir
        self.env = _child_env()

    def fly(self, index: int) -> dict[str, Any]:
        cfg = self.cfg
        seed = cfg.seed + index
        mdir = self.work_dir / f"mission-{index:03d}"
        mdir.mkdir(parents=True, exist_ok=True)
        layout = mission_layout(cfg.scenario, cfg.seed, index)
        scenario_file = mdir / "scenario.yaml"
        dump(dataclasses.replace(cfg.scenario, layout=layout, random=None), scenario_file)
        truth = mdir / "truth.jsonl"
        cpu0 = _children_cpu_s()
        t0 = time.monotonic()
        pids: dict[str, int] = {}
        sitl: Optional[Child] = None
        if cfg.connect is None:
            sitl, endpoints = self._start_world(mdir, scenario_file, truth, seed)
            pids["sitl"] = sitl.pid
        else:
            endpoints = dict(zip([r.value for r in ROLES], cfg.connect))
        companions = self._start_companions(index, mdir, scenario_file, endpoints)
        pids.update({c.name: c.pid for c in companions})
        _log.info("mission %d: started %s", index, " ".join(f"{k}={v}" for k, v in pids.items()))
        timed_out = self._watch(index, sitl, companions, t0)
        wall_s = time.monotonic() - t0
        statuses = {c.name: self._companion_status(c, mdir) for c in companions}
        row: dict[str, Any] = {"index": index, "seed": seed, "pids": pids, "wall_time_s": round(wall_s, 3),
                               "cpu_s": round(_children_cpu_s() - cpu0, 3), "companions": statuses}
        if sitl is not None:
            try:
                record = read_mission(truth)
            except TruthLogError as exc:
                raise ChildFailed(f"mission {index}: {exc}") from None
            row.update(_outcome(record, cfg.scenario.cost_limit))
            if cfg.plot_path is not None:
                self._plot(index, layout, record)
        else:
            row.update(_outcome_from_companions(statuses))
        flight = [s.get("flight_wall_s") for s in statuses.values() if s.get("flight_wall_s")]
        if flight and row.get("sim_time_s"):
            row["flight_wall_s"] = round(max(flight), 3)
            row["speed_x"] = round(row["sim_time_s"] / max(flight), 1)
        # The CPU the flight took, world and companions, start-up excluded (what bench_bridge reports).
        cpus = [s.get("flight_cpu_s") for s in statuses.values()] + ([row.get("world_flight_cpu_s")] if sitl is not None else [])
        if cpus and all(c is not None for c in cpus):
            row["flight_cpu_s"] = round(sum(cpus), 3)
        if timed_out:
            row["end"] = "timeout"
            row["success"] = False
        return row

    def _start_world(self, mdir: Path, scenario_file: Path, truth: Path, seed: int) -> tuple[Child, dict[str, str]]:
        cfg = self.cfg
        argv = [sys.executable, "-m", "sim_vehicles", "--scenario", str(scenario_file), "--seed", str(seed), "--base-port", "0",
                "--truth-log", str(truth), "--linger-s", "0.2"]
        if cfg.lockstep:
            argv += ["--lockstep", "--setpoint-timeout-s", str(LOCKSTEP_SETPOINT_TIMEOUT_S)]
        else:  # the world waits for all three companions, as in lockstep, then runs at real time x speedup
            argv += ["--speedup", repr(cfg.speedup), "--hold-start"]
        if cfg.signing_key_path is not None:
            argv += ["--signing-key", str(cfg.signing_key_path)]
        log = mdir / "sitl.log"
        sitl = self.children.start("sitl", argv, log_path=log, stdout_pipe=True, env=self.env)
        endpoints = self._read_endpoints(sitl, log)
        return sitl, endpoints

    def _read_endpoints(self, sitl: Child, log: Path) -> dict[str, str]:
        """The ``<role> sysid=N udpout:HOST:PORT`` lines the SITL prints before ``ready``."""
        out = sitl.process.stdout
        assert out is not None
        deadline = time.monotonic() + self.cfg.startup_timeout_s
        buf = b""
        while b"\nready" not in b"\n" + buf:
            if sitl.poll() is not None:
                buf += out.read() or b""
                if b"\nready" in b"\n" + buf:
                    break
                raise ChildFailed(f"the SITL world exited with code {sitl.poll()} before it was ready: {_tail(log) or buf.decode(errors='replace').strip()}")
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise ChildFailed(f"the SITL world was not ready within {self.cfg.startup_timeout_s:g} s")
            if select.select([out], [], [], min(remaining, 0.2))[0]:
                chunk = os.read(out.fileno(), 4096)
                buf += chunk
        endpoints: dict[str, str] = {}
        for line in buf.decode(errors="replace").splitlines():
            parts = line.split()
            if len(parts) == 3 and parts[0] in {r.value for r in ROLES} and parts[1].startswith("sysid="):
                endpoints[parts[0]] = parts[2]
        if set(endpoints) != {r.value for r in ROLES}:
            raise ChildFailed(f"the SITL world did not print its three endpoints: {buf.decode(errors='replace').strip()!r}")
        return endpoints

    def _start_companions(self, index: int, mdir: Path, scenario_file: Path, endpoints: dict[str, str]) -> list[Child]:
        cfg = self.cfg
        out = []
        for role in ROLES:
            name = role.value
            argv = [sys.executable, "-m", "mavlink_bridge.companion", "--connect", endpoints[name], "--role", name,
                    "--scenario", str(scenario_file), "--status-json", str(mdir / f"{name}.status.json")]
            argv += ["--model", str(pilot_file(cfg.models, role))] if cfg.models is not None else ["--pilot", GUIDANCE]
            if cfg.lockstep:
                argv += ["--lockstep"]
            if cfg.lean_telemetry:
                argv += ["--lean-telemetry"]
            if cfg.tlog_dir is not None:
                argv += ["--tlog", str(cfg.tlog_dir / f"mission-{index:03d}" / f"{name}.tlog")]
            if cfg.signing_key_path is not None:
                argv += ["--signing-key", str(cfg.signing_key_path)]
            out.append(self.children.start(name, argv, log_path=mdir / f"{name}.log", env=self.env))
        return out

    def _watch(self, index: int, sitl: Optional[Child], companions: list[Child], t0: float) -> bool:
        """Wait for the mission to end; True if it timed out. Raises ChildFailed when a child crashes."""
        deadline = t0 + self.cfg.mission_timeout_s
        while True:
            for c in companions:
                rc = c.poll()
                if rc is not None and rc != 0:
                    raise ChildFailed(f"mission {index}: companion {c.name} (pid {c.pid}) exited with code {rc}: {_tail(c.log_path)}")
            if sitl is not None:
                rc = sitl.poll()
                if rc is not None:
                    if rc != 0:
                        raise ChildFailed(f"mission {index}: the SITL world (pid {sitl.pid}) exited with code {rc}: {_tail(sitl.log_path)}")
                    break
            elif all(c.poll() is not None for c in companions):
                break
            if time.monotonic() > deadline:
                _log.error("mission %d: not over after %.0f s: stopping it", index, self.cfg.mission_timeout_s)
                self.children.stop(([sitl] if sitl else []) + companions)
                return True
            time.sleep(0.02)
        # The world has ended: the companions heard it (HIT / MSN_END) and are on their way out.
        grace_end = time.monotonic() + 5.0
        while any(c.poll() is None for c in companions) and time.monotonic() < grace_end:
            time.sleep(0.02)
        late = [c for c in companions if c.poll() is None]
        if late:
            _log.warning("mission %d: %s still running after the world ended: stopping", index, ", ".join(c.name for c in late))
            self.children.stop(late)
        for c in companions:
            rc = c.poll()
            if rc not in (0, None) and c not in late:
                raise ChildFailed(f"mission {index}: companion {c.name} (pid {c.pid}) exited with code {rc}: {_tail(c.log_path)}")
        return False

    @staticmethod
    def _companion_status(c: Child, mdir: Path) -> dict[str, Any]:
        path = mdir / f"{c.name}.status.json"
        out: dict[str, Any] = {"exit_code": c.poll()}
        try:
            data = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            out["status"] = "unknown"
            return out
        counters = data.get("counters", {})
        lat = data.get("latency_ms", {})
        out.update(
            {
                "status": data.get("status"),
                "vehicle_time_s": data.get("vehicle_time_s"),
                "flight_wall_s": data.get("flight_wall_s"),
                "flight_cpu_s": data.get("flight_cpu_s"),
                "control_steps": counters.get("control_steps"),
                "holds": counters.get("holds"),
                "restarts": counters.get("restarts"),
                "latency_p50_ms": lat.get("p50"),
                "latency_p99_ms": lat.get("p99"),
            }
        )
        return out

    def _plot(self, index: int, layout: Layout, record: MissionRecord) -> None:
        from tssac_core.plots import plot_mission

        cfg = self.cfg
        assert cfg.plot_path is not None
        path = cfg.plot_path
        if cfg.episodes > 1:
            path = path.with_name(f"{path.stem}-{index:03d}{path.suffix or '.png'}")
        path.parent.mkdir(parents=True, exist_ok=True)
        r = cfg.scenario.ranges
        verdict = "success" if record.success else record.end
        cost = ", ".join(f"{k} {v:g}" for k, v in record.cost.items())
        plot_mission(path, layout, record.tracks_km(), (r.strike_launch_km, r.detect_km, r.sam_launch_km, r.sam_detect_km),
                     record.event_markers_km(), title=f"{cfg.scenario.name} #{index} (SITL): {verdict}, {record.sim_time_s:.0f} s, cost {cost}",
                     area_km=cfg.scenario.area_km)


def _outcome(record: MissionRecord, cost_limit: float) -> dict[str, Any]:
    tasks = record.task_done()
    return {
        "success": record.success,
        "end": record.end,
        "steps": record.steps,
        "sim_time_s": round(record.sim_time_s, 3),
        "cost": record.cost,
        "within_cost_limit": {k: v <= cost_limit for k, v in record.cost.items()},
        "task_done": tasks,
        "failsafe_steps": record.failsafe_steps,
        "world_flight_cpu_s": record.summary.get("flight_cpu_s") if record.summary is not None else None,
    }


def _outcome_from_companions(statuses: dict[str, dict[str, Any]]) -> dict[str, Any]:
    ends = [s.get("status") for s in statuses.values()]
    success = "success" in ends
    end = "success" if success else next((e for e in ends if e in ("geofence", "episode_cap")), "unknown")
    times = [s["vehicle_time_s"] for s in statuses.values() if s.get("vehicle_time_s") is not None]
    return {"success": success, "end": end, "sim_time_s": max(times) if times else None, "cost": None}


def summarise(rows: list[dict[str, Any]], cfg: FlyConfig) -> dict[str, Any]:
    """The results JSON: success_rate, mean_cost, episodes, per-role figures and the missions."""
    n = len(rows)
    out: dict[str, Any] = {
        "success_rate": float(np.mean([bool(r.get("success")) for r in rows])) if n else None,
        "mean_cost": None,
        "episodes": n,
        "episodes_requested": cfg.episodes,
        "mean_mission_time_s": None,
        "roles": {},
    }
    times = [r["sim_time_s"] for r in rows if r.get("sim_time_s") is not None]
    if times:
        out["mean_mission_time_s"] = float(np.mean(times))
    costed = [r for r in rows if r.get("cost")]
    if costed:
        out["mean_cost"] = float(np.mean([[r["cost"][role.value] for role in ROLES] for r in costed]))
    for role in ROLES:
        name = role.value
        fig: dict[str, Any] = {}
        if costed:
            costs = np.array([r["cost"][name] for r in costed])
            fig.update({"mean_cost": float(costs.mean()), "max_cost": float(costs.max()),
                        "within_cost_limit": float((costs <= cfg.scenario.cost_limit).mean())})
            fig["task_success_rate"] = float(np.mean([bool(r.get("task_done", {}).get(name)) for r in costed]))
        p50 = [r["companions"][name]["latency_p50_ms"] for r in rows if r.get("companions", {}).get(name, {}).get("latency_p50_ms") is not None]
        p99 = [r["companions"][name]["latency_p99_ms"] for r in rows if r.get("companions", {}).get(name, {}).get("latency_p99_ms") is not None]
        if p50:
            fig["latency_p50_ms"] = float(np.median(p50))
            fig["latency_p99_ms"] = float(np.max(p99))
        out["roles"][name] = fig
    out.update(
        {
            "pilot": str(cfg.models) if cfg.models is not None else GUIDANCE,
            "scenario": str(cfg.scenario_path),
            "seed": cfg.seed,
            "clock": ("connected, lockstep" if cfg.lockstep else "connected") if cfg.connect is not None
            else ("lockstep" if cfg.lockstep else f"speedup {cfg.speedup:g}"),
            "cost_limit": cfg.scenario.cost_limit,
            "signing": cfg.signing_key_path is not None,
            "missions": rows,
        }
    )
    return out


# ----------------------------------------------------------------------------- entry point


class _Terminated(KeyboardInterrupt):
    """SIGTERM, handled like Ctrl-C."""


def _on_sigterm(signum: int, _frame: Optional[FrameType]) -> None:
    raise _Terminated()


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(levelname)s %(name)s: %(message)s")
    try:
        cfg = config_from_args(argv)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except (UsageError, ScenarioError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as exc:
        print(f"{PROG}: error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    previous = signal.signal(signal.SIGTERM, _on_sigterm)
    children = ChildProcesses()
    rows: list[dict[str, Any]] = []
    error: Optional[str] = None
    interrupted = False
    code = 0
    tmp: Optional[tempfile.TemporaryDirectory[str]] = None
    started = time.monotonic()
    try:
        if cfg.logs_dir is not None:
            work = cfg.logs_dir
            work.mkdir(parents=True, exist_ok=True)
        else:
            tmp = tempfile.TemporaryDirectory(prefix="tssac-fly-")
            work = Path(tmp.name)
        if cfg.signing_key_path is None and cfg.scenario.link.signing:
            cfg = dataclasses.replace(cfg, signing_key_path=make_signing_key(work))
        runner = MissionRunner(cfg, children, work)
        with tqdm(total=cfg.episodes, desc="missions", unit="mission", disable=not cfg.progress, file=sys.stderr) as bar:
            for i in range(cfg.episodes):
                row = runner.fly(i)
                rows.append(row)
                children.forget_finished()
                bar.update(1)
                bar.set_postfix(success=f"{np.mean([bool(r.get('success')) for r in rows]):.0%}")
                if row.get("end") == "timeout":
                    error = f"mission {i} did not end within {cfg.mission_timeout_s:g} s"
                    code = EXIT_FAILED
                    break
    except KeyboardInterrupt:
        interrupted = True
        code = EXIT_INTERRUPTED
    except ChildFailed as exc:
        error = str(exc)
        code = EXIT_FAILED
    except (UsageError, ScenarioError) as exc:
        error = str(exc)
        code = EXIT_BAD_INPUT
    finally:
        # No second signal may cut the clean-up short: the children are in their own sessions.
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        previous_int = signal.signal(signal.SIGINT, signal.SIG_IGN)
        children.stop_all()
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, previous_int)
        summary = summarise(rows, cfg)
        summary["interrupted"] = interrupted
        summary["error"] = error
        summary["wall_time_s"] = round(time.monotonic() - started, 3)
        if cfg.json_path is not None:
            write_json(cfg.json_path, summary)
        if tmp is not None:
            tmp.cleanup()
    _report(summary, cfg)
    if interrupted:
        print(f"interrupted after {len(rows)} of {cfg.episodes} missions" + (f"; wrote {cfg.json_path}" if cfg.json_path else ""), file=sys.stderr)
    if error is not None:
        print(f"{PROG}: error: {error}", file=sys.stderr)
    return code


def _report(summary: dict[str, Any], cfg: FlyConfig) -> None:
    n = summary["episodes"]
    if not n:
        return
    cost = "unknown" if summary["mean_cost"] is None else f"{summary['mean_cost']:.2f}"
    print(f"success rate {summary['success_rate']:.1%} over {n} missions, mean hazard cost per UAV {cost} "
          f"(limit {cfg.scenario.cost_limit:g}), mean mission time {summary['mean_mission_time_s'] or 0:.1f} s")
    for role, fig in summary["roles"].items():
        parts = [f"  {role:6s}"]
        if "mean_cost" in fig:
            parts.append(f"task {fig['task_success_rate']:.0%}  cost mean {fig['mean_cost']:.2f} max {fig['max_cost']:.0f}")
        if "latency_p50_ms" in fig:
            parts.append(f"latency p50 {fig['latency_p50_ms']:.2f} ms p99 {fig['latency_p99_ms']:.2f} ms")
        print("  ".join(parts))
    for r in summary["missions"]:
        speed = f", {r['speed_x']:.0f}x real time in flight" if r.get("speed_x") else ""
        print(f"  mission {r['index']}: {'success' if r.get('success') else r.get('end')}, {r.get('sim_time_s') or 0:.1f} s simulated, "
              f"{r['wall_time_s']:.1f} s wall{speed}")
    if cfg.json_path is not None:
        print(f"wrote {cfg.json_path}")


if __name__ == "__main__":
    sys.exit(main())
