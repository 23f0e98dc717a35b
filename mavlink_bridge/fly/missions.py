"""One mission's processes: the SITL world and three companions, started, watched and scored."""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import re
import resource
import select
import signal
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from mavlink_bridge.fly.config import REPO, FlyConfig
from mavlink_bridge.fly.report import animate_mission_record, plot_mission_record
from mavlink_bridge.fly.scoring import outcome, outcome_from_companions
from mavlink_bridge.mission_log import TruthLogError, read_mission
from mavlink_bridge.processes import Child, ChildProcesses
from tssac_core.deploy.numpy_actor import pilot_file
from tssac_core.sim.scenario import ROLES, Layout, Scenario, dump, sample_layout

_log = logging.getLogger("mavlink_bridge.fly")

LOCKSTEP_SETPOINT_TIMEOUT_S = 5.0
"""Under lockstep the vehicles' setpoint failsafe counts wall seconds at the step barrier: 5 s keeps a
companion that a loaded machine paused for a moment in the loop (failsafes are still counted)."""


class ChildFailed(Exception):
    """A child process crashed or a mission hung; ``str()`` is one line."""


def mission_layout(scenario: Scenario, seed: int, index: int) -> Layout:
    """The layout of mission ``index``: the fixed one, or ``sample_layout`` with ``default_rng(seed + index)``."""
    return sample_layout(scenario, np.random.default_rng(seed + index))


def _child_env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    env.setdefault("OMP_NUM_THREADS", "1")  # small networks: threads only fight each other
    return env


def _children_cpu_s() -> float:
    """User + system CPU seconds of every child reaped so far (the mission's processes, once it is over)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


_ALARMING = re.compile(r"\b(CRITICAL|ERROR|WARNING)\b|error:|Error\b|Exception\b")


def last_meaningful_line(path: Path | None, max_chars: int = 240) -> str:
    """The line of a child's log that best says why it died: a traceback's exception line or the last
    error or warning, else the last line ("" for a missing or empty log). Traceback frames are skipped."""
    if path is None or not path.exists():
        return ""
    lines = [ln.rstrip() for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    candidates = [ln for ln in lines if not ln[0].isspace() and not ln.startswith("Traceback (most recent call last)")]
    alarming = [ln for ln in candidates if _ALARMING.search(ln)]
    line = (alarming or candidates or [""])[-1]
    return line if len(line) <= max_chars else line[: max_chars - 3] + "..."


def child_failure(what: str, child: Child, rc: int, when: str = "") -> str:
    """One line: which child died, how (its exit code, or the signal that killed it), and its last words."""
    if rc < 0:
        try:
            name = signal.Signals(-rc).name
        except ValueError:
            name = "unknown signal"
        how = f"was killed by signal {-rc} ({name})"
    else:
        how = f"exited with code {rc}"
    how += f" {when}" if when else ""
    last = last_meaningful_line(child.log_path)
    said = f'; its last log line: "{last}"' if last else "; its log is empty"
    return f"{what} (pid {child.pid}) {how}{said}"


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
        sitl: Child | None = None
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
        row: dict[str, Any] = {
            "index": index,
            "seed": seed,
            "pids": pids,
            "wall_time_s": round(wall_s, 3),
            "cpu_s": round(_children_cpu_s() - cpu0, 3),
            "companions": statuses,
        }
        if sitl is not None:
            try:
                record = read_mission(truth)
            except TruthLogError as exc:
                raise ChildFailed(f"mission {index}: {exc}") from None
            row.update(outcome(record, cfg.scenario.cost_limit))
            if cfg.plot_path is not None:
                row["plot"] = str(plot_mission_record(cfg, index, layout, record))
            if cfg.animate_path is not None:
                row["animation"] = str(animate_mission_record(cfg, index, layout, record))
        else:
            row.update(outcome_from_companions(statuses))
        flight = [float(f) for s in statuses.values() if (f := s.get("flight_wall_s"))]
        if flight and row.get("sim_time_s"):
            row["flight_wall_s"] = round(max(flight), 3)
            row["speed_x"] = round(row["sim_time_s"] / max(flight), 1)
        # The CPU the flight took, world and companions, start-up excluded (what bench_bridge reports).
        cpus = [s.get("flight_cpu_s") for s in statuses.values()] + (
            [row.get("world_flight_cpu_s")] if sitl is not None else []
        )
        known = [float(c) for c in cpus if c is not None]
        if cpus and len(known) == len(cpus):
            row["flight_cpu_s"] = round(sum(known), 3)
        if timed_out:
            row["end"] = "timeout"
            row["success"] = False
        return row

    def _start_world(self, mdir: Path, scenario_file: Path, truth: Path, seed: int) -> tuple[Child, dict[str, str]]:
        cfg = self.cfg
        argv = [
            sys.executable,
            "-m",
            "sim_vehicles",
            "--scenario",
            str(scenario_file),
            "--seed",
            str(seed),
            "--base-port",
            "0",
            "--truth-log",
            str(truth),
            "--linger-s",
            "0.2",
        ]
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
                printed = "" if last_meaningful_line(log) else f"; it printed {buf.decode(errors='replace').strip()!r}"
                raise ChildFailed(
                    child_failure("the SITL world", sitl, sitl.poll() or 0, "before it was ready") + printed
                )
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
            raise ChildFailed(
                f"the SITL world did not print its three endpoints: {buf.decode(errors='replace').strip()!r}"
            )
        return endpoints

    def _start_companions(self, index: int, mdir: Path, scenario_file: Path, endpoints: dict[str, str]) -> list[Child]:
        cfg = self.cfg
        out = []
        for role in ROLES:
            name = role.value
            argv = [
                sys.executable,
                "-m",
                "mavlink_bridge.companion",
                "--connect",
                endpoints[name],
                "--role",
                name,
                "--scenario",
                str(scenario_file),
                "--status-json",
                str(mdir / f"{name}.status.json"),
            ]
            argv += ["--model", str(pilot_file(cfg.models, role))] if cfg.models is not None else ["--pilot", cfg.pilot]
            if cfg.shield:
                argv += ["--shield"]
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

    def _watch(self, index: int, sitl: Child | None, companions: list[Child], t0: float) -> bool:
        """Wait for the mission to end; True if it timed out. Raises ChildFailed when a child crashes."""
        deadline = t0 + self.cfg.mission_timeout_s
        while True:
            for c in companions:
                rc = c.poll()
                if rc is not None and rc != 0:
                    raise ChildFailed(f"mission {index}: " + child_failure(f"companion {c.name}", c, rc))
            if sitl is not None:
                rc = sitl.poll()
                if rc is not None:
                    if rc != 0:
                        raise ChildFailed(f"mission {index}: " + child_failure("the SITL world", sitl, rc))
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
            _log.warning(
                "mission %d: %s still running after the world ended: stopping", index, ", ".join(c.name for c in late)
            )
            self.children.stop(late)
        for c in companions:
            rc = c.poll()
            if rc not in (0, None) and c not in late:
                raise ChildFailed(f"mission {index}: " + child_failure(f"companion {c.name}", c, rc))
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
                "shield": data.get("shield"),
            }
        )
        return out
