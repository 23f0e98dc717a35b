"""The mission-reset protocol: the world and the companions fly mission after mission in the same processes, with
the same missions as processes started for each (tssac_core.wire.mission_reset, fly's crew)."""

from __future__ import annotations

import dataclasses
import json
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from mavlink_bridge.fly.config import DEFAULT_MODELS, config_from_args
from mavlink_bridge.fly.crew import Crew, LineReader
from mavlink_bridge.fly.mission_runner import ChildFailed, MissionRunner
from mavlink_bridge.processes.children import ChildProcesses
from tssac_core.sim.scenario import dump, load
from tssac_core.wire.mission_reset import MissionInput, NextMission, ResetError
from tssac_core.wire.truth_log_schema import HEADER, STEP, SUMMARY

REPO = Path(__file__).resolve().parents[1]
RANDOM = REPO / "scenarios" / "random.yaml"
sys.path.insert(0, str(Path(__file__).resolve().parent))
from sitl_helpers import parent_pid, quick_strike_scenario  # noqa: E402
from test_fly import _alive  # noqa: E402

# ------------------------------------------------------------------------------ the lines


def test_a_mission_line_round_trips() -> None:
    mission = NextMission(7, Path("/m/scenario.yaml"), seed=12, truth_log=Path("/m/truth.jsonl"), log=Path("/m/x.log"))
    line = mission.to_line()
    assert line.endswith("\n") and line.count("\n") == 1
    assert NextMission.from_line(line) == mission
    assert "status_json" not in json.loads(line)  # unset paths are left out
    assert NextMission.from_line('{"quit": true}') is None


@pytest.mark.parametrize(
    ("line", "says"),
    [
        ("mission 3", "not JSON"),
        ("[1, 2]", "not a JSON object"),
        ('{"index": 1}', "'index' and a 'scenario'"),
        ('{"index": "1", "scenario": "a.yaml"}', "'index' and a 'scenario'"),
        ('{"index": 1, "scenario": "a.yaml", "seed": 1.5}', "'seed'"),
        ('{"index": 1, "scenario": "a.yaml", "truth_log": 3}', "'truth_log'"),
        ('{"index": 1, "scenario": "a.yaml", "reboot": 1}', "unknown fields: reboot"),
    ],
)
def test_a_malformed_mission_line_is_one_clear_error(line: str, says: str) -> None:
    with pytest.raises(ResetError, match=says) as err:
        NextMission.from_line(line)
    assert "\n" not in str(err.value)


def test_waiting_for_a_mission_ends_at_quit_end_of_input_or_a_stop() -> None:
    read_fd, write_fd = os.pipe()
    try:
        missions = MissionInput(read_fd)
        os.write(
            write_fd,
            ("\n" + NextMission(2, Path("s.yaml")).to_line() + NextMission(3, Path("t.yaml")).to_line()).encode(),
        )
        got = [missions.next(lambda: False, timeout_s=5.0) for _ in range(2)]
        assert [m.index if m else None for m in got] == [2, 3]  # two lines in one read; the blank one skipped
        t0 = time.monotonic()
        assert missions.next(lambda: time.monotonic() - t0 > 0.3, poll_s=0.05) is None  # a stop request
        assert 0.3 <= time.monotonic() - t0 < 3.0
        os.write(write_fd, b'{"quit": true}\n')
        assert missions.next(lambda: False, timeout_s=5.0) is None  # quit
        os.write(write_fd, NextMission(4, Path("u.yaml")).to_line().encode().rstrip())
        os.close(write_fd)
        write_fd = -1
        last = missions.next(lambda: False, timeout_s=5.0)
        assert last is not None and last.index == 4  # a last line without its newline still counts
        assert missions.next(lambda: False, timeout_s=5.0) is None  # end of input
    finally:
        os.close(read_fd)
        if write_fd >= 0:
            os.close(write_fd)


# ------------------------------------------------------------------------------ the world


class _Lines:
    """A child's standard output, line by line, read straight from the pipe (no buffer hides a line from select)."""

    def __init__(self, proc: subprocess.Popen[bytes]) -> None:
        assert proc.stdout is not None
        self.fd = proc.stdout.fileno()
        self.buffer = b""

    def until(self, prefix: str, timeout_s: float = 60.0) -> str:
        deadline = time.monotonic() + timeout_s
        while True:
            while b"\n" in self.buffer:
                line, _, self.buffer = self.buffer.partition(b"\n")
                if line.decode().startswith(prefix):
                    return line.decode()
            assert time.monotonic() < deadline, f"no {prefix!r} line within {timeout_s} s"
            if select.select([self.fd], [], [], 0.2)[0]:
                chunk = os.read(self.fd, 65536)
                assert chunk, f"the world ended its output before a {prefix!r} line"
                self.buffer += chunk


@pytest.mark.sitl
@pytest.mark.timeout(120)
def test_a_serving_world_flies_the_next_mission_it_is_told_and_refuses_a_bad_line(tmp_path: Path) -> None:
    """Real time at 2,000x with nobody in the loop: each mission flies itself to its end in a moment."""
    scenario = quick_strike_scenario(tmp_path)
    argv = [sys.executable, "-m", "sim_vehicles", "--scenario", str(scenario), "--speedup", "2000", "--serve"]
    argv += ["--base-port", "0", "--linger-s", "0", "--truth-log", str(tmp_path / "t0.jsonl")]
    proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO)
    try:
        assert proc.stdin is not None
        lines = _Lines(proc)
        lines.until("end reason=")
        for index in (1, 2):
            truth = tmp_path / f"t{index}.jsonl"
            proc.stdin.write(NextMission(index, scenario, seed=40 + index, truth_log=truth).to_line().encode())
            proc.stdin.flush()
            assert lines.until("ready ").startswith(f"ready mission={index} scenario=quick seed={40 + index}")
            lines.until("end reason=")
        proc.stdin.write(b"mission three\n")
        proc.stdin.flush()
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    assert proc.returncode == 2
    # On a loaded machine the world may fall behind its 2,000x clock and say so (a pacing warning): not the error.
    said = [line for line in err.decode().strip().splitlines() if "sim_vehicles.clock.pacing WARNING" not in line]
    assert len(said) == 1 and said[0].startswith("python -m sim_vehicles: error: mission line is not JSON"), said
    records = [[json.loads(line) for line in (tmp_path / f"t{i}.jsonl").read_text().splitlines()] for i in (0, 1, 2)]
    headers = [r[0] for r in records]
    assert [h["type"] for h in headers] == [HEADER] * 3 and [h["seed"] for h in headers] == [0, 41, 42]
    assert len({tuple(h["ports"]) for h in headers}) == 1  # the same sockets
    assert all(r[-1]["type"] == SUMMARY and r[-1]["steps"] > 0 for r in records)
    first_steps = [next(x for x in r if x["type"] == STEP)["step"] for r in records]
    assert first_steps == [1, 1, 1]  # every mission starts at the world's first step


# ---------------------------------------------------------------------- whole campaigns


def _steps(record: Path) -> list[dict[str, Any]]:
    return [r for r in map(json.loads, record.read_text().splitlines()) if r["type"] == STEP]


def _fly_json(
    tmp_path: Path, name: str, *extra: str, scenario: Path = RANDOM, episodes: int = 2, seed: int = 31
) -> dict[str, Any]:
    """``fly`` the shipped team (logs in ``tmp_path/name``); its JSON."""
    out = tmp_path / f"{name}.json"
    argv = ["--scenario", str(scenario), "--models", str(DEFAULT_MODELS), "--episodes", str(episodes)]
    argv += ["--seed", str(seed)]
    argv += ["--logs", str(tmp_path / name), "--json", str(out), "--no-progress", *extra]
    proc = subprocess.run(
        [sys.executable, "-m", "mavlink_bridge.fly", *argv], cwd=REPO, capture_output=True, text=True, timeout=400
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(out.read_text())


@pytest.mark.slow
@pytest.mark.sitl
@pytest.mark.timeout(600)
def test_one_crew_flies_a_campaign_with_the_missions_of_fresh_processes(tmp_path: Path) -> None:
    # random.yaml's layouts, each mission cut at 40 s of flight (400 steps): what is compared does not depend on how
    # the missions end, and a whole mission there is 250 s.
    scenario = tmp_path / "random-40s.yaml"
    dump(dataclasses.replace(load(RANDOM), episode_steps=400), scenario)
    kept = _fly_json(tmp_path, "kept", scenario=scenario)
    fresh = _fly_json(tmp_path, "fresh", "--fresh-processes", scenario=scenario)
    assert len({tuple(m["pids"].values()) for m in kept["missions"]}) == 1  # one world, three companions
    assert len({tuple(m["pids"].values()) for m in fresh["missions"]}) == 2
    layouts = []
    for index in (0, 1):
        name = f"mission-{index:03d}"
        steps = _steps(tmp_path / "kept" / name / "truth.jsonl")
        assert steps == _steps(tmp_path / "fresh" / name / "truth.jsonl")  # step by step the same flight
        assert len(steps) > 100
        layouts.append(json.loads((tmp_path / "kept" / name / "truth.jsonl").read_text().splitlines()[0])["layout"])
        for role, status in kept["missions"][index]["companions"].items():
            assert status == {**fresh["missions"][index]["companions"][role], **_timing(status)}, role
    assert layouts[0] != layouts[1]  # the reset took the next mission's layout
    assert not [pid for m in kept["missions"] for pid in m["pids"].values() if _alive(pid)]


def _timing(status: dict[str, Any]) -> dict[str, Any]:
    """The fields of a companion's status that measure the machine, not the mission."""
    keys = ("flight_wall_s", "flight_cpu_s", "latency_p50_ms", "latency_p99_ms")
    return {k: status[k] for k in keys}


@pytest.mark.sitl
@pytest.mark.timeout(300)
def test_a_crew_process_whose_death_fly_learns_by_a_broken_pipe_is_named_with_its_signal(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """A companion dies just as fly tells it the next mission: its exit status has not reached fly yet (the check
    before telling sees it running), the pipe breaks, and the mission's error still says what killed it. The
    companions already told the mission stop at fly's SIGTERM, though it came while they set the mission up."""
    quick = quick_strike_scenario(tmp_path)
    cfg = config_from_args(["--scenario", str(quick), "--pilot", "guidance", "--episodes", "2"])
    children = ChildProcesses()
    runner = MissionRunner(cfg, children, tmp_path / "work")
    try:
        assert runner.fly(0)["success"] and runner.crew is not None
        detect = next(c for c in runner.crew.children if c.name == "detect")
        os.kill(detect.pid, signal.SIGKILL)
        assert detect.process.wait(10) == -signal.SIGKILL
        told: list[str] = []  # its exit status is not known until fly has tried to tell it the next mission
        real_tell = Crew.tell

        def tell(crew: Crew, reader: LineReader, mission: NextMission | None) -> None:
            told.append(reader.child.name)
            real_tell(crew, reader, mission)

        monkeypatch.setattr(Crew, "tell", tell)
        monkeypatch.setattr(detect, "poll", lambda: -signal.SIGKILL if "detect" in told else None)
        with pytest.raises(ChildFailed, match=r"mission 1: companion detect \(pid \d+\) was killed by signal 9"):
            runner.fly(1)
        assert runner.crew is None
        assert not [r.message for r in caplog.records if "did not stop" in r.message]
    finally:
        runner.close()
        children.stop_all()


@pytest.mark.sitl
@pytest.mark.timeout(300)
def test_a_crew_process_that_died_between_missions_is_replaced(tmp_path: Path) -> None:
    """A companion killed between missions, then the fork server the crew came from: each time the next mission
    flies with a new crew (and a new server), and nothing is left running."""
    quick = quick_strike_scenario(tmp_path)
    cfg = config_from_args(["--scenario", str(quick), "--pilot", "guidance", "--episodes", "3"])
    children = ChildProcesses()
    runner = MissionRunner(cfg, children, tmp_path / "work")
    servers = []
    try:
        first = runner.fly(0)
        assert first["success"] and runner.crew is not None and runner.forks is not None
        servers.append(runner.forks.child.pid)
        detect = next(c for c in runner.crew.children if c.name == "detect")
        assert parent_pid(detect.pid) == runner.forks.child.pid  # the crew is forked from the server
        detect.process.kill()
        detect.process.wait(10)
        second = runner.fly(1)
        assert runner.forks.child.pid == servers[0]  # the server lives on
        os.kill(servers[0], signal.SIGKILL)  # the crew dies with it (SIGTERM)
        runner.forks.child.process.wait(10)
        third = runner.fly(2)
        servers.append(runner.forks.child.pid)
    finally:
        runner.close()
        children.stop_all()
    assert second["success"] and third["success"]
    assert not set(first["pids"].values()) & set(second["pids"].values())  # a new crew flew it
    assert not set(second["pids"].values()) & set(third["pids"].values())
    assert servers[0] != servers[1]
    flown = [pid for row in (first, second, third) for pid in row["pids"].values()]
    assert not [pid for pid in flown + servers if _alive(pid)]
