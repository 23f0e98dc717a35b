"""One mission's processes: the SITL world and three companions, started, watched and scored."""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import re
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from mavlink_bridge.fly.child_configs import (
    COMPANION_MODULE,
    WORLD_MODULE,
    companion_config,
    tlog_path,
    world_config,
)
from mavlink_bridge.fly.config import REPO, FlyConfig
from mavlink_bridge.fly.crew import Crew, CrewError, LineReader, wait_readable
from mavlink_bridge.fly.mission_log import TruthLogError, read_mission
from mavlink_bridge.fly.mission_row import CompanionStatus, MissionRow, Outcome
from mavlink_bridge.fly.report import animate_mission_record, plot_mission_record
from mavlink_bridge.fly.scoring import outcome, outcome_from_companions
from mavlink_bridge.link.signing_key import read_signing_key
from mavlink_bridge.processes.children import Child, ChildProcesses
from mavlink_bridge.processes.fork_server import AVAILABLE as FORK_SERVER_AVAILABLE
from mavlink_bridge.processes.fork_server import ForkServer, ForkServerError
from tssac_core.common.files import create_exclusively, private_directory
from tssac_core.sim.lagged_starts import response_start_check
from tssac_core.sim.scenario import ROLES, Layout, Role, Scenario, StartCheck, dump, load, sample_layout
from tssac_core.wire.mission_reset import NextMission

_log = logging.getLogger("mavlink_bridge.fly")

CREW_DEATH_WAIT_S = 2.0
"""How long fly waits for the exit status of a crew process whose standard input broke."""
TLOGS_INCOMPLETE = "INCOMPLETE"
"""The file beside a mission's tlogs (``--tlog DIR/mission-NNN/``) while they are not the whole mission: written when
the mission starts, removed when it has ended with every tlog whole. Left there (by an interruption, a failure, a
kill), it says why in one line; a mission whose tlog could not all be written says which."""

CREW_IMPORTS = (WORLD_MODULE, COMPANION_MODULE, "mavlink_bridge.companion.machine")
"""What a crew's fork server imports once for the world and the three companions it forks (their start-up is
mostly imports: filterpy with scipy.stats, pymavlink, numpy)."""


class ChildFailed(Exception):
    """A child process crashed or a mission hung; ``str()`` is one line."""


class WorldRefused(ChildFailed):
    """The SITL world refused its configuration before it was ready (its exit code 2: an airframe that does not load,
    a scenario it cannot fly); ``str()`` is the world's own one line. Bad input, not a crash."""


EXIT_BAD_INPUT = 2
"""The exit code of a command that refused its input (tssac_core.common.cli.EXIT_BAD_INPUT)."""


def mission_layout(scenario: Scenario, seed: int, index: int, starts: StartCheck | None = None) -> Layout:
    """The layout of mission ``index``: the fixed one, or ``sample_layout`` with ``default_rng(seed + index)``;
    ``starts``: the further check of its starts a monitor predicting with an airframe's response needs
    (:func:`tssac_core.sim.lagged_starts.response_start_check`)."""
    return sample_layout(scenario, np.random.default_rng(seed + index), start_check=starts)


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


def _send_config(child: Child, config_json: str, keep_open: bool) -> None:
    """Write a child's configuration, one line, to its standard input; close that unless ``keep_open`` (the missions
    follow). A child that died first does not read it: its exit status says why, where fly watches it."""
    stdin = child.process.stdin
    assert stdin is not None, f"{child.name}: standard input is not piped"
    try:
        stdin.write(config_json.encode() + b"\n")
        stdin.flush()
        if not keep_open:
            stdin.close()
    except OSError:  # a broken pipe: it has exited
        pass


def _write_mark(path: Path, text: str) -> None:
    with os.fdopen(create_exclusively(path), "w", encoding="utf-8") as fh:
        fh.write(text)


def _settle_tlog_mark(marker: Path, row: MissionRow) -> None:
    """A mission that ended: its tlogs are whole (the mark goes) unless one was cut or the mission timed out."""
    lost = [f"{name}: {error}" for name, s in row["companions"].items() if (error := s.get("write_error"))]
    if lost:
        try:  # the mark is ours, in a directory of ours: rewritten in place, its page reused on a full disk
            with open(marker, "w", encoding="utf-8") as fh:
                fh.write(f"mission {row['index']} (seed {row['seed']}): {'; '.join(lost)}\n")
        except OSError as exc:  # the mark made at the start stays; the results JSON names the loss
            _log.error("%s: %s", marker, exc.strerror or exc)
    elif row.get("end") != "timeout":
        marker.unlink(missing_ok=True)


class MissionRunner:
    """Starts and watches the processes of each mission (see the module docstring)."""

    def __init__(self, cfg: FlyConfig, children: ChildProcesses, work_dir: Path, children_cpu: bool = True) -> None:
        """``children_cpu`` False: other runners' children end in this process too, so the CPU of a mission of fresh
        processes (taken from every reaped child's usage) is not known (None); a kept crew's is read per process."""
        self.cfg = cfg
        self.children = children
        self.work_dir = work_dir
        self.children_cpu = children_cpu
        self.starts = response_start_check(cfg.scenario, cfg.airframe_response)
        """The further check of each layout's starts when the monitors predict with an airframe's response."""
        self.env = _child_env()
        self.crew: Crew | None = None
        """The processes kept alive across missions (``cfg.persistent``), None until the first or after a failure."""
        self.forks: ForkServer | None = None
        """The server that forks each crew's processes, started with the first crew."""
        self.signing_key: bytes | None = None
        """The run's signing key, once read (:meth:`_signing_key`)."""

    def close(self) -> None:
        """Let the crew's processes quit (they exit on their own; the caller's stop_all reaps what does not), then
        the fork server."""
        try:
            self._close_crew()
        finally:
            forks, self.forks = self.forks, None
            if forks is not None:
                forks.close()

    def _close_crew(self) -> None:
        crew, self.crew = self.crew, None
        if crew is None:
            return
        for reader in crew.readers:
            try:
                crew.tell(reader, None)
            except CrewError:
                pass
        deadline = time.monotonic() + 2.0
        while any(c.poll() is None for c in crew.children) and time.monotonic() < deadline:
            time.sleep(0.01)
        self.children.stop(crew.children)

    def fly(self, index: int) -> MissionRow:
        cfg = self.cfg
        seed = cfg.seed + index
        mdir = private_directory(self.work_dir / f"mission-{index:03d}", "--logs")
        marker = self._mark_tlogs(index, seed)
        layout = mission_layout(cfg.scenario, cfg.seed, index, self.starts)
        scenario_file = mdir / "scenario.yaml"
        dump(dataclasses.replace(cfg.scenario, layout=layout, random=None), scenario_file)
        truth = mdir / "truth.jsonl"
        t0 = time.monotonic()
        pids: dict[str, int] = {}
        sitl: Child | None = None
        cpu_s: float | None
        if cfg.connect is None and cfg.persistent:
            crew, timed_out, cpu_s = self._fly_with_crew(index, mdir, scenario_file, truth, seed, t0)
            sitl, companions = crew.world.child, [r.child for r in crew.companions]
            pids = {c.name: c.pid for c in crew.children}
        else:
            cpu0 = _children_cpu_s()
            if cfg.connect is None:
                world, endpoints = self._start_world(mdir, scenario_file, truth, seed)
                sitl = world.child
                pids["sitl"] = sitl.pid
            else:
                endpoints = dict(zip([r.value for r in ROLES], cfg.connect))
            companions = self._start_companions(index, mdir, scenario_file, endpoints)
            pids.update({c.name: c.pid for c in companions})
            _log.info("mission %d: started %s", index, " ".join(f"{k}={v}" for k, v in pids.items()))
            timed_out = self._watch(index, sitl, companions, t0)
            cpu_s = _children_cpu_s() - cpu0 if self.children_cpu else None
        wall_s = time.monotonic() - t0
        statuses = {c.name: self._companion_status(c, mdir) for c in companions}
        record = None
        if sitl is not None:
            try:
                record = read_mission(truth)
            except TruthLogError as exc:
                raise ChildFailed(f"mission {index}: {exc}") from None
        ended: Outcome = (
            outcome(record, cfg.scenario.cost_limit) if record is not None else outcome_from_companions(statuses)
        )
        row: MissionRow = {
            "index": index,
            "seed": seed,
            "pids": pids,
            "wall_time_s": round(wall_s, 3),
            "cpu_s": None if cpu_s is None else round(cpu_s, 3),
            "companions": statuses,
            **ended,
        }
        if record is not None:
            if cfg.plot_path is not None:
                row["plot"] = str(plot_mission_record(cfg, index, layout, record))
            if cfg.animate_path is not None:
                row["animation"] = str(animate_mission_record(cfg, index, layout, record))
        flight = [float(f) for s in statuses.values() if (f := s.get("flight_wall_s"))]
        if flight and (sim_time_s := row["sim_time_s"]):
            row["flight_wall_s"] = round(max(flight), 3)
            row["speed_x"] = round(sim_time_s / max(flight), 1)
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
        if marker is not None:
            _settle_tlog_mark(marker, row)
        return row

    def _mark_tlogs(self, index: int, seed: int) -> Path | None:
        """Mark mission ``index``'s tlogs incomplete until it ends (:data:`TLOGS_INCOMPLETE`); None without tlogs."""
        if self.cfg.tlog_dir is None:
            return None
        folder = private_directory(self.cfg.tlog_dir / f"mission-{index:03d}", "--tlog")
        marker = folder / TLOGS_INCOMPLETE
        _write_mark(marker, f"mission {index} (seed {seed}) did not end: its tlogs stop where it was stopped\n")
        return marker

    def _start_world(
        self, mdir: Path, scenario_file: Path, truth: Path, seed: int, serve: bool = False
    ) -> tuple[LineReader, dict[str, str]]:
        """The world (the reader of its output) and its vehicles' connection strings; it is started with its typed
        configuration (:func:`~mavlink_bridge.fly.child_configs.world_config`) on standard input."""
        config = world_config(self.cfg, load(scenario_file), seed, truth, self._signing_key())
        argv = ["--config-json", "-"] + (["--serve"] if serve else [])
        log = mdir / "sitl.log"
        sitl = self._launch(
            "sitl", WORLD_MODULE, argv, log, stdout_pipe=True, serve=serve, config_json=config.to_json()
        )
        reader = LineReader(sitl)
        return reader, self._read_endpoints(reader, log)

    def _read_endpoints(self, reader: LineReader, log: Path) -> dict[str, str]:
        """The ``<role> sysid=N udpout:HOST:PORT`` lines the SITL prints before ``ready``."""
        sitl = reader.child
        deadline = time.monotonic() + self.cfg.startup_timeout_s
        seen: list[str] = []
        while not (seen and seen[-1].startswith("ready")):
            if reader.lines:
                seen.append(reader.lines.popleft())
                continue
            if reader.eof:  # it closed its output: it is exiting
                try:
                    rc = sitl.process.wait(5.0)
                except subprocess.TimeoutExpired:
                    rc = 0
                printed = "" if last_meaningful_line(log) else f"; it printed {' | '.join(seen)!r}"
                said = last_meaningful_line(log)
                if rc == EXIT_BAD_INPUT and said:
                    raise WorldRefused(f"the SITL world refused the mission: {said.partition(': error: ')[2] or said}")
                raise ChildFailed(child_failure("the SITL world", sitl, rc, "before it was ready") + printed)
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise ChildFailed(f"the SITL world was not ready within {self.cfg.startup_timeout_s:g} s")
            wait_readable([reader], min(remaining, 0.2))
        endpoints: dict[str, str] = {}
        for line in seen:
            parts = line.split()
            if len(parts) == 3 and parts[0] in {r.value for r in ROLES} and parts[1].startswith("sysid="):
                endpoints[parts[0]] = parts[2]
        if set(endpoints) != {r.value for r in ROLES}:
            raise ChildFailed(f"the SITL world did not print its three endpoints: {' | '.join(seen)!r}")
        return endpoints

    def _start_companions(
        self, index: int, mdir: Path, scenario_file: Path, endpoints: dict[str, str], serve: bool = False
    ) -> list[Child]:
        """The three companions, each started with its typed configuration (:mod:`mavlink_bridge.fly.child_configs`)
        on standard input; they fly the scenario file the world flies."""
        scenario = load(scenario_file)
        out = []
        for role in ROLES:
            name = role.value
            config = companion_config(
                self.cfg,
                role,
                endpoints[name],
                scenario,
                status_json=mdir / f"{name}.status.json",
                tlog=tlog_path(self.cfg, index, role),
                signing_key=self._signing_key(),
            )
            argv = ["--config-json", "-"] + (["--serve"] if serve else [])
            log = mdir / f"{name}.log"
            out.append(self._launch(name, COMPANION_MODULE, argv, log, serve, serve, config.to_json()))
        return out

    def _signing_key(self) -> bytes | None:
        """The run's signing key (read once from ``cfg.signing_key_path``), None when it flies unsigned."""
        if self.signing_key is None and self.cfg.signing_key_path is not None:
            self.signing_key = read_signing_key(self.cfg.signing_key_path)
        return self.signing_key

    def _launch(
        self,
        name: str,
        module: str,
        args: list[str],
        log: Path,
        stdout_pipe: bool,
        serve: bool,
        config_json: str | None = None,
    ) -> Child:
        """``python -m module args``: a crew's process (``serve``: it reads its next missions on standard input) is
        forked from the crew's fork server; a mission's own process starts afresh, as a user's would. ``config_json``:
        the first line of its standard input, its configuration (then closed, unless it serves)."""
        if not serve or not FORK_SERVER_AVAILABLE:
            argv = [sys.executable, "-m", module, *args]
            stdin_pipe = serve or config_json is not None
            child = self.children.start(
                name, argv, log_path=log, stdout_pipe=stdout_pipe, stdin_pipe=stdin_pipe, env=self.env
            )
        else:
            child = self._fork(name, module, args, log, stdout_pipe)
        if config_json is not None:
            _send_config(child, config_json, keep_open=serve)
        return child

    def _fork(self, name: str, module: str, args: list[str], log: Path, stdout_pipe: bool) -> Child:
        """``python -m module args`` forked from the crew's fork server (started, or started again, here)."""
        if self.forks is None or not self.forks.alive:
            if self.forks is not None:
                _log.warning("the fork server (pid %d) has ended: starting a new one", self.forks.child.pid)
                self.forks.close()
            # Its log goes beside the crew's first logs, in the directory of the mission the crew starts with.
            self.forks = ForkServer(self.children, CREW_IMPORTS, log_path=log.parent / "fork-server.log", env=self.env)
        try:
            return self.forks.start(
                name,
                module,
                args,
                log_path=log,
                stdin_pipe=True,
                stdout_pipe=stdout_pipe,
                timeout_s=self.cfg.startup_timeout_s,
            )
        except ForkServerError as exc:
            last = last_meaningful_line(self.forks.child.log_path)
            said = f'; its last log line: "{last}"' if last else ""
            raise ChildFailed(f"cannot start {name}: {exc}{said}") from None

    # ------------------------------------------------------------------------- persistent processes

    def _fly_with_crew(
        self, index: int, mdir: Path, scenario_file: Path, truth: Path, seed: int, t0: float
    ) -> tuple[Crew, bool, float | None]:
        """Fly one mission with the crew (started for it when there is none): the crew, whether the mission timed
        out, and the CPU seconds its processes used for it. Raises ChildFailed; a failed or timed-out mission's
        crew is stopped, and the next mission starts a new one."""
        try:
            crew, cpu0 = self._crew_for(index, mdir, scenario_file, truth, seed)
            timed_out = self._watch_crew(index, crew, t0)
        except CrewError as exc:
            # Its standard input broke: it has died, and how it died is the error (its exit status may reach us a
            # moment after the broken pipe, from a fork server's notice or the kernel's reaping).
            try:
                exc.child.process.wait(CREW_DEATH_WAIT_S)
                if self.crew is not None:
                    self._check_crew_alive(index, self.crew)
            except subprocess.TimeoutExpired:
                pass
            finally:
                self._drop_crew()
            raise ChildFailed(f"mission {index}: {exc}") from None
        except ChildFailed:
            self._drop_crew()
            raise
        cpu1 = crew.cpu_s()
        if timed_out:
            self._drop_crew()
        return crew, timed_out, None if cpu0 is None or cpu1 is None else cpu1 - cpu0

    def _crew_for(
        self, index: int, mdir: Path, scenario_file: Path, truth: Path, seed: int
    ) -> tuple[Crew, float | None]:
        """The crew, told mission ``index`` (or started with it), and its CPU seconds before the mission."""
        if self.crew is not None and any(c.poll() is not None for c in self.crew.children):
            _log.warning("mission %d: a process of the last mission's crew has exited: starting a new crew", index)
            self._drop_crew()
        elif self.crew is not None and self.forks is not None and not self.forks.alive:
            _log.warning("mission %d: the crew's fork server has ended (its crew with it): starting a new crew", index)
            self._drop_crew()
        if self.crew is None:
            world, endpoints = self._start_world(mdir, scenario_file, truth, seed, serve=True)
            companions = self._start_companions(index, mdir, scenario_file, endpoints, serve=True)
            self.crew = Crew(world, [LineReader(c) for c in companions])
            _log.info("mission %d: started %s", index, " ".join(f"{c.name}={c.pid}" for c in self.crew.children))
            return self.crew, 0.0
        crew = self.crew
        cpu0 = crew.cpu_s()
        _log.info("mission %d: reset %s", index, " ".join(f"{c.name}={c.pid}" for c in crew.children))
        crew.ended.clear()
        crew.tell(crew.world, NextMission(index, scenario_file, seed=seed, truth_log=truth, log=mdir / "sitl.log"))
        # The world has reset (forgotten its clients, drained its sockets) when it says ready: only then may the
        # companions start the mission, or a late datagram of theirs could reach the new mission.
        deadline = time.monotonic() + self.cfg.startup_timeout_s
        while crew.world.take("ready") is None:
            self._check_crew_alive(index, crew)
            if time.monotonic() > deadline:
                raise ChildFailed(
                    f"mission {index}: the SITL world did not reset within {self.cfg.startup_timeout_s:g} s"
                )
            wait_readable([crew.world], 0.2)
        for reader in crew.companions:
            name = reader.child.name
            tlog = tlog_path(self.cfg, index, Role(name))
            crew.tell(
                reader,
                NextMission(
                    index, scenario_file, status_json=mdir / f"{name}.status.json", tlog=tlog, log=mdir / f"{name}.log"
                ),
            )
        return crew, cpu0

    def _watch_crew(self, index: int, crew: Crew, t0: float) -> bool:
        """Wait until the world and every companion printed the mission's ``end`` line; True if it timed out."""
        deadline = t0 + self.cfg.mission_timeout_s
        grace_end: float | None = None
        while True:
            for reader in crew.readers:
                if reader.child.name not in crew.ended and reader.take("end ") is not None:
                    crew.ended.add(reader.child.name)
            self._check_crew_alive(index, crew)
            if len(crew.ended) == len(crew.readers):
                return False
            now = time.monotonic()
            if crew.world.child.name in crew.ended:
                # The world has ended: the companions heard it (HIT / MSN_END) and are confirming it.
                grace_end = grace_end or now + 5.0
                if now > grace_end:
                    late = [r.child.name for r in crew.companions if r.child.name not in crew.ended]
                    _log.warning("mission %d: %s still flying after the world ended: stopping", index, ", ".join(late))
                    self._drop_crew()
                    return False
            if now > deadline:
                _log.error("mission %d: not over after %.0f s: stopping it", index, self.cfg.mission_timeout_s)
                return True
            wait_readable(crew.readers, 0.05)

    def _check_crew_alive(self, index: int, crew: Crew) -> None:
        """ChildFailed for a process of the crew that exited with an error, or exited at all before its end line."""
        for child in crew.children:
            rc = child.poll()
            if rc is None:
                continue
            what = "the SITL world" if child is crew.world.child else f"companion {child.name}"
            if rc != 0:
                raise ChildFailed(f"mission {index}: " + child_failure(what, child, rc))
            if child.name not in crew.ended:
                raise ChildFailed(f"mission {index}: " + child_failure(what, child, rc, "before the mission ended"))

    def _drop_crew(self) -> None:
        crew, self.crew = self.crew, None
        if crew is not None:
            self.children.stop(crew.children)

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
    def _companion_status(c: Child, mdir: Path) -> CompanionStatus:
        path = mdir / f"{c.name}.status.json"
        exit_code = c.poll()
        try:
            data = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            return {"exit_code": exit_code, "status": "unknown"}
        counters = data.get("counters", {})
        lat = data.get("latency_ms", {})
        out: CompanionStatus = {
            # A process kept for the next mission has not exited: its status file has the mission's exit code.
            "exit_code": data.get("exit_code", exit_code),
            "status": data.get("status"),
            "vehicle_time_s": data.get("vehicle_time_s"),
            "flight_wall_s": data.get("flight_wall_s"),
            "flight_cpu_s": data.get("flight_cpu_s"),
            "control_steps": counters.get("control_steps"),
            "setpoints_sent": counters.get("setpoints_sent"),
            "ticks_granted": counters.get("ticks_granted"),
            "holds": counters.get("holds"),
            "restarts": counters.get("restarts"),
            "latency_p50_ms": lat.get("p50"),
            "latency_p99_ms": lat.get("p99"),
            "shield": data.get("shield"),
        }
        if isinstance(said := data.get("vehicle_limits"), dict):
            out["vehicle_limits"] = said
        if data.get("write_error") is not None:
            out["write_error"] = str(data["write_error"])
        return out
