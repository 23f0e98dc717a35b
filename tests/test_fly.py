"""``python -m mavlink_bridge.fly``: whole missions in SITL worlds it starts, and the processes it leaves behind (none).

The mission tests run fly as a subprocess (it starts its own world and companions, each in its own
process group, on OS-assigned ports on 127.0.0.1) and check afterwards that none of the processes
it started is still alive: their pids come from fly's JSON and its log lines.
"""

from __future__ import annotations

import json
import os
import re
import select
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink import mavutil
from sitl_helpers import cmdline, quick_strike_scenario, running

from mavlink_bridge.companion.machine import LEAN_OFF
from mavlink_bridge.fly import cli as fly
from mavlink_bridge.fly.config import DEFAULT_MODELS
from mavlink_bridge.fly.mission_runner import mission_layout
from tssac_core.common.cli import UsageError
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.pilots import GUIDANCE
from tssac_core.sim.scenario import load, sample_layout

REPO = Path(__file__).resolve().parents[1]
STRIKE = REPO / "scenarios" / "strike.yaml"
RANDOM = REPO / "scenarios" / "random.yaml"
JSON_KEYS = {"success_rate", "mean_cost", "episodes", "roles", "missions"}


def _env() -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(REPO))


def _alive(pid: int) -> bool:
    """A live (not zombie) process with this pid runs our code (a reused pid would not)."""
    line = cmdline(pid)
    return running(pid) and (b"sim_vehicles" in line or b"mavlink_bridge" in line)


def _pids(results: dict[str, Any]) -> list[int]:
    return [pid for m in results["missions"] for pid in m["pids"].values()]


def _start_fly(args: list[str]) -> subprocess.Popen[bytes]:
    # SIGINT back to its default in the child: a test run started in the background (`cmd &` in a
    # script) inherits SIGINT ignored, and Python then installs no KeyboardInterrupt handler, so fly
    # would not see the Ctrl-C these tests send it.
    return subprocess.Popen(
        [sys.executable, "-m", "mavlink_bridge.fly", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=REPO,
        env=_env(),
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )


def _read_until(proc: subprocess.Popen[bytes], pattern: str, timeout_s: float) -> tuple[str, re.Match[str]]:
    """fly's stderr up to the first line matching ``pattern``."""
    assert proc.stderr is not None
    buf = ""
    deadline = time.monotonic() + timeout_s
    while True:
        match = re.search(pattern, buf)
        if match:
            return buf, match
        remaining = deadline - time.monotonic()
        assert remaining > 0 and proc.poll() is None, f"no {pattern!r} in fly's output: {buf}"
        if select.select([proc.stderr], [], [], min(remaining, 0.2))[0]:
            buf += os.read(proc.stderr.fileno(), 65536).decode(errors="replace")


def _stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.kill()
        proc.wait(10)


# ------------------------------------------------------------------------------ missions


@pytest.mark.sitl
@pytest.mark.timeout(300)
def test_fly_guidance_strike_mission_in_lockstep(tmp_path: Path) -> None:
    out, tlogs, plot = tmp_path / "fly.json", tmp_path / "tlogs", tmp_path / "mission.png"
    scenario = quick_strike_scenario(tmp_path, strike_km=25.0)
    t0 = time.monotonic()
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "mavlink_bridge.fly",
            "--scenario",
            str(scenario),
            "--pilot",
            "guidance",
            "--lockstep",
            "--json",
            str(out),
            "--tlog",
            str(tlogs),
            "--plot",
            str(plot),
            "--no-progress",
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=_env(),
        timeout=280,
    )
    wall_s = time.monotonic() - t0
    assert proc.returncode == 0, proc.stderr[-2000:]
    results = json.loads(out.read_text())
    assert JSON_KEYS <= set(results) and results["episodes"] == 1 and results["error"] is None
    assert results["success_rate"] == 1.0 and results["signing"] is True  # a key made for the run, by default
    mission = results["missions"][0]
    assert mission["success"] and mission["end"] == "success" and all(mission["task_done"].values())
    # The batched world flies the same mission (the same layout, no GPS noise) within 1% of its steps.
    batched = fly_missions(load(scenario), [GUIDANCE] * 3, episodes=1, seed=0)
    assert batched.success.all() and batched.cost.sum() == 0
    assert mission["steps"] == pytest.approx(batched.time_s[0] * 10, rel=0.01)
    assert mission["sim_time_s"] == pytest.approx(mission["steps"] / 10)
    assert results["mean_cost"] == pytest.approx(np.mean(list(mission["cost"].values())))
    assert set(results["roles"]) == {"decoy", "detect", "strike"}
    for role, comp in mission["companions"].items():
        assert comp["status"] == "success" and comp["exit_code"] == 0 and comp["holds"] == 0, (role, comp)
        assert comp["latency_p50_ms"] > 0
    assert not mission["failsafe_steps"]
    print(
        f"strike mission in lockstep: {wall_s:.1f} s wall, {mission['sim_time_s']:.0f} s simulated, "
        f"{mission.get('speed_x')}x in flight"
    )
    # One .tlog per vehicle, readable by pymavlink's mavlogdump.py.
    for role in ("decoy", "detect", "strike"):
        tlog = tlogs / "mission-000" / f"{role}.tlog"
        dump_ = subprocess.run(
            [
                sys.executable,
                "-m",
                "pymavlink.tools.mavlogdump",
                "--types",
                "HEARTBEAT,COMMAND_ACK,SET_POSITION_TARGET_LOCAL_NED",
                str(tlog),
            ],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert dump_.returncode == 0, dump_.stderr[-500:]
        lines = dump_.stdout.splitlines()
        assert sum("SET_POSITION_TARGET_LOCAL_NED" in ln for ln in lines) >= 0.97 * mission["steps"]  # one a step
        assert any("HEARTBEAT" in ln for ln in lines) and any("COMMAND_ACK" in ln for ln in lines)
        # fly's own lockstep world, lean telemetry by default: once flying, only the streams the companion reads.
        flying = _types_after_setpoints(tlog, 100)
        assert {"HEARTBEAT", "SYSTEM_TIME", "LOCAL_POSITION_NED", "NAMED_VALUE_INT"} <= flying, (role, flying)
        assert not flying & set(LEAN_OFF), (role, flying)
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and plot.stat().st_size > 20_000
    assert not [pid for pid in _pids(results) if _alive(pid)]


def _types_after_setpoints(tlog: Path, setpoints: int) -> set[str]:
    """The message types a companion's tlog holds after its first ``setpoints`` setpoints."""
    log = mavutil.mavlink_connection(str(tlog))
    seen, types = 0, set()
    while (msg := log.recv_match()) is not None:
        kind = msg.get_type()
        if seen >= setpoints:
            types.add(kind)
        seen += kind == "SET_POSITION_TARGET_LOCAL_NED"
    log.close()
    return types


@pytest.mark.sitl
@pytest.mark.timeout(240)
def test_fly_speedup_signed_random_layouts(tmp_path: Path) -> None:
    key = tmp_path / "key.hex"
    key.write_text(bytes(range(32)).hex() + "\n")
    scen = load(quick_strike_scenario(tmp_path))
    # A "random" scenario whose draws land on the quick layout would need a custom range; instead check
    # the layout rule directly and fly the quick layout with a real-time world, signing on.
    rnd = load(RANDOM)
    assert mission_layout(rnd, 3, 2) == sample_layout(rnd, np.random.default_rng(5))
    assert mission_layout(scen, 3, 2) == scen.layout
    out = tmp_path / "fly.json"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "mavlink_bridge.fly",
            "--scenario",
            str(quick_strike_scenario(tmp_path)),
            "--pilot",
            "guidance",
            "--speedup",
            "10",
            "--episodes",
            "2",
            "--seed",
            "4",
            "--signing-key",
            str(key),
            "--json",
            str(out),
            "--no-progress",
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=_env(),
        timeout=220,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    results = json.loads(out.read_text())
    assert results["episodes"] == 2 and results["success_rate"] == 1.0 and results["signing"] is True
    assert results["clock"] == "speedup 10" and [m["seed"] for m in results["missions"]] == [4, 5]
    assert not [pid for pid in _pids(results) if _alive(pid)]


def _start_guidance_fly(
    tmp_path: Path, out: Path, episodes: int, more: tuple[str, ...] = ()
) -> subprocess.Popen[bytes]:
    """``fly`` of the guidance controller over ``episodes`` short missions, JSON to ``out``, in the background."""
    scenario = quick_strike_scenario(tmp_path, strike_km=25.0)
    return _start_fly(
        [
            "--scenario",
            str(scenario),
            "--pilot",
            "guidance",
            "--episodes",
            str(episodes),
            "--json",
            str(out),
            "--no-progress",
            *more,
        ]
    )


@pytest.mark.slow
@pytest.mark.sitl
@pytest.mark.timeout(240)
def test_fly_sigint_stops_every_process_and_writes_the_finished_missions(tmp_path: Path) -> None:
    """... and the tlogs of the mission it cut are marked so (an INCOMPLETE file beside them), those of the finished
    missions not."""
    out, tlogs = tmp_path / "fly.json", tmp_path / "tlogs"
    proc = _start_guidance_fly(tmp_path, out, episodes=5, more=("--tlog", str(tlogs)))
    try:
        crew = r"mission \d+: (?:started|reset) sitl=(\d+) decoy=(\d+) detect=(\d+) strike=(\d+)"
        log, _ = _read_until(proc, crew.replace("\\d+:", "1:", 1), 150)
        running = {int(p) for m in re.finditer(crew, log) for p in m.groups()}
        time.sleep(1.0)  # mission 1 in flight
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        _stop(proc)
    assert proc.returncode == 130, err.decode()[-2000:]
    results = json.loads(out.read_text())
    assert results["interrupted"] is True and results["episodes"] >= 1 and results["episodes_requested"] == 5
    assert all(m["success"] for m in results["missions"])
    assert len(running) == 4 and not [pid for pid in running if _alive(pid)]  # one crew flew both missions
    cut = results["episodes"]  # the mission in flight
    marked = sorted(p.parent.name for p in tlogs.glob("mission-*/INCOMPLETE"))
    assert marked == [f"mission-{cut:03d}"], marked
    assert "did not end" in (tlogs / f"mission-{cut:03d}" / "INCOMPLETE").read_text()
    assert all((tlogs / f"mission-{i:03d}" / "decoy.tlog").stat().st_size > 0 for i in range(cut + 1))


@pytest.fixture
def full_disk(tmp_path: Path) -> Iterator[Path]:
    """A 64 KiB file system (tmpfs; root only): a disk that fills during a mission."""
    tiny = tmp_path / "tiny"
    tiny.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(tiny)]).returncode:
        pytest.skip("needs root to mount a small tmpfs")
    try:
        yield tiny
    finally:
        subprocess.run(["umount", str(tiny)], check=True)


@pytest.mark.sitl
@pytest.mark.timeout(180)
def test_tlogs_cut_by_a_full_disk_are_an_error_in_the_exit_code_the_json_and_beside_the_tlogs(
    tmp_path: Path, full_disk: Path
) -> None:
    out = tmp_path / "fly.json"
    argv = ["--scenario", str(quick_strike_scenario(tmp_path, 25.0)), "--pilot", "guidance", "--tlog", str(full_disk)]
    proc = subprocess.run(
        [sys.executable, "-m", "mavlink_bridge.fly", *argv, "--json", str(out), "--no-progress"],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=_env(),
        timeout=170,
    )
    assert proc.returncode == 1, proc.stderr[-2000:]
    results = json.loads(out.read_text())
    assert "No space left on device" in results["error"] and results["error"].startswith("mission 0: ")
    errors = [ln for ln in proc.stderr.splitlines() if "error:" in ln]
    assert len(errors) == 1 and "tlog" in errors[0] and "cut" in errors[0], errors
    assert results["missions"], (results["error"], proc.stderr[-3000:])
    cut = [name for name, s in results["missions"][0]["companions"].items() if s.get("write_error")]
    assert cut, results["missions"][0]["companions"]
    assert "No space left on device" in (full_disk / "mission-000" / "INCOMPLETE").read_text()


def _error_after_killing(proc: subprocess.Popen[bytes], pid: int, role: str) -> str:
    """SIGKILL ``role``'s companion ``pid`` of a running ``fly``: fly exits 1 with one error line, which names the
    companion and the signal (returned)."""
    try:
        os.kill(pid, signal.SIGKILL)
        _, err_b = proc.communicate(timeout=60)
    finally:
        _stop(proc)
    err = err_b.decode()
    assert proc.returncode == 1, err[-2000:]
    errors = [ln for ln in err.splitlines() if "error:" in ln]
    assert len(errors) == 1 and f"companion {role}" in errors[0] and "killed by signal 9 (SIGKILL)" in errors[0], errors
    return errors[0]


@pytest.mark.sitl
@pytest.mark.timeout(240)
def test_fly_stops_everything_when_a_companion_crashes(tmp_path: Path) -> None:
    out = tmp_path / "fly.json"
    proc = _start_guidance_fly(tmp_path, out, episodes=3)
    try:
        _, match = _read_until(proc, r"mission 0: started sitl=(\d+) decoy=(\d+) detect=(\d+) strike=(\d+)", 120)
        pids = [int(p) for p in match.groups()]
        time.sleep(2.0)  # in flight
    except BaseException:
        _stop(proc)
        raise
    error = _error_after_killing(proc, pids[2], "detect")  # the detect UAV's companion dies
    assert "its last log line: " in error or error.endswith("its log is empty")
    results = json.loads(out.read_text())
    assert results["error"] and "companion detect" in results["error"]
    # The crew is kept across missions, so the kill may land in a later mission than the first (a lockstep mission
    # can end within the 2 s): the JSON holds exactly the missions finished before the one that crashed.
    crashed = re.match(r"mission (\d+): ", results["error"])
    assert crashed is not None and results["episodes"] == int(crashed.group(1)) < 3, results["error"]
    assert not [pid for pid in pids if _alive(pid)]


@pytest.mark.sitl
@pytest.mark.timeout(180)
def test_a_killed_fly_leaves_no_orphans(tmp_path: Path) -> None:
    proc = _start_fly(
        ["--scenario", str(quick_strike_scenario(tmp_path, strike_km=25.0)), "--pilot", "guidance", "--no-progress"]
    )
    try:
        _, match = _read_until(proc, r"mission 0: started sitl=(\d+) decoy=(\d+) detect=(\d+) strike=(\d+)", 120)
        pids = [int(p) for p in match.groups()]
        time.sleep(1.0)
        proc.kill()  # no clean-up possible: the children learn it from PR_SET_PDEATHSIG
        proc.wait(10)
    finally:
        _stop(proc)
    deadline = time.monotonic() + 15.0
    while [pid for pid in pids if _alive(pid)] and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not [pid for pid in pids if _alive(pid)]


# ------------------------------------------------------------------- crews side by side


def _truth_steps(log: Path) -> list[str]:
    return [line for line in log.read_text().splitlines() if line.startswith('{"type":"step"')]


@pytest.mark.slow
@pytest.mark.sitl
@pytest.mark.timeout(240)
def test_two_crews_side_by_side_fly_the_serial_missions(tmp_path: Path) -> None:
    """``fly --workers 2``: two crews of this process, each taking the next mission as it ends; the rows and every
    truth log's steps are the serial run's, mission by mission, and each mission's plot is drawn."""
    scenario = quick_strike_scenario(tmp_path, strike_km=25.0)  # one short mission; each seed its own GPS noise
    args = ["--scenario", str(scenario), "--pilot", "guidance", "--episodes", "3", "--seed", "41", "--no-progress"]
    runs = {}
    for name, extra in (("serial", []), ("side", ["--workers", "2", "--plot", str(tmp_path / "side.png")])):
        assert fly.main([*args, *extra, "--json", str(tmp_path / f"{name}.json"), "--logs", str(tmp_path / name)]) == 0
        runs[name] = json.loads((tmp_path / f"{name}.json").read_text())
    keys = ("index", "seed", "success", "end", "steps", "sim_time_s", "cost", "task_done")
    serial, side = ([{k: m[k] for k in keys} for m in runs[name]["missions"]] for name in ("serial", "side"))
    assert side == serial and [m["seed"] for m in serial] == [41, 42, 43]
    truth = {
        name: [_truth_steps(tmp_path / name / f"mission-{i:03d}" / "truth.jsonl") for i in range(3)]
        for name in ("serial", "side")
    }
    assert truth["side"] == truth["serial"] and all(truth["serial"])
    assert len({tuple(steps) for steps in truth["serial"]}) == 3  # three different missions, not one three times
    worlds = [m["pids"]["sitl"] for m in runs["side"]["missions"]]
    assert len(set(worlds)) == 2  # two crews, one of which flew two missions
    assert [Path(m["plot"]).name for m in runs["side"]["missions"]] == [f"side-{i:03d}.png" for i in range(3)]
    assert all(Path(m["plot"]).stat().st_size > 10_000 for m in runs["side"]["missions"])  # drawn one at a time
    assert runs["side"]["missions"][0]["cpu_s"] is not None  # a kept crew's CPU is read per process
    assert not [pid for pid in _pids(runs["side"]) if _alive(pid)]


def _two_crews_flying(tmp_path: Path, out: Path) -> tuple[subprocess.Popen[bytes], list[list[int]]]:
    """``fly --workers 2`` of eight short guidance missions, once both crews fly: the process and each crew's
    pids (world, decoy, detect, strike)."""
    proc = _start_fly(
        ["--scenario", str(quick_strike_scenario(tmp_path, strike_km=25.0)), "--pilot", "guidance", "--episodes", "8"]
        + ["--workers", "2", "--json", str(out), "--no-progress"]
    )
    started = r"mission \d+: started sitl=(\d+) decoy=(\d+) detect=(\d+) strike=(\d+)"
    try:
        log, _ = _read_until(proc, f"{started}[\\s\\S]*{started}", 150)
    except BaseException:
        _stop(proc)
        raise
    crews = [[int(p) for p in m.groups()] for m in re.finditer(started, log)]
    time.sleep(1.0)  # both in flight
    return proc, crews


@pytest.mark.sitl
@pytest.mark.timeout(240)
def test_sigterm_stops_both_crews_and_writes_the_finished_missions(tmp_path: Path) -> None:
    out = tmp_path / "fly.json"
    proc, crews = _two_crews_flying(tmp_path, out)
    try:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        _stop(proc)
    assert proc.returncode == 130, err.decode()[-2000:]
    assert b"Traceback" not in err, err.decode()[-2000:]  # the crews' threads let their processes go quietly
    results = json.loads(out.read_text())
    assert results["interrupted"] is True and results["episodes"] < 8 and results["episodes_requested"] == 8
    assert all(m["success"] for m in results["missions"])
    assert len(crews) == 2 and not [pid for crew in crews for pid in crew if _alive(pid)]


@pytest.mark.sitl
@pytest.mark.timeout(120)
def test_every_uav_that_leaves_the_area_is_counted_out(tmp_path: Path) -> None:
    """Straight pilots on the quick layout: the decoy (heading north) and the detect UAV (heading east) both reach the
    area's edge 35 km out at the same step, which ends the mission; each is counted out, whatever its index (a FENCE
    event's value is the UAV's index: counting only values of 1 counted the detect UAV alone)."""
    out = tmp_path / "fly.json"
    args = ["--scenario", str(quick_strike_scenario(tmp_path, strike_km=25.0)), "--pilot", "straight"]
    assert fly.main([*args, "--episodes", "1", "--no-progress", "--json", str(out)]) == 0
    mission = json.loads(out.read_text())["missions"][0]
    assert mission["end"] == "geofence" and mission["left_area"] == {"decoy": 1, "detect": 1, "strike": 0}


@pytest.mark.sitl
@pytest.mark.timeout(300)
def test_a_campaign_killed_outright_keeps_its_finished_missions_and_resume_completes_it(tmp_path: Path) -> None:
    """SIGKILL leaves fly no time to write: what it wrote as the missions ended (``--checkpoint-s 0``: after each) is
    what survives, a campaign not yet whole, and ``--resume`` flies only the rest."""
    out = tmp_path / "fly.json"
    args = ["--scenario", str(quick_strike_scenario(tmp_path, strike_km=25.0)), "--pilot", "guidance"]
    args += ["--episodes", "4", "--json", str(out), "--no-progress"]
    proc = _start_fly([*args, "--checkpoint-s", "0"])
    try:
        log, _ = _read_until(proc, r"mission 1: \w+ sitl=", 150)  # mission 0 ended (and was written) before it
        proc.kill()
        proc.wait(10)
    finally:
        _stop(proc)
    kept = json.loads(out.read_text())
    assert 1 <= kept["episodes"] < 4 and kept["episodes_requested"] == 4 and kept["interrupted"] is False, log
    crew = list(kept["missions"][0]["pids"].values())
    deadline = time.monotonic() + 30  # the crew follows its parent (PR_SET_PDEATHSIG)
    while time.monotonic() < deadline and [pid for pid in crew if _alive(pid)]:
        time.sleep(0.1)
    assert fly.main([*args, "--resume"]) == 0
    resumed = json.loads(out.read_text())
    assert [m["index"] for m in resumed["missions"]] == [0, 1, 2, 3] and all(m["success"] for m in resumed["missions"])
    assert resumed["missions"][: kept["episodes"]] == kept["missions"]


@pytest.mark.sitl
@pytest.mark.timeout(240)
def test_a_crash_in_one_crew_stops_both(tmp_path: Path) -> None:
    out = tmp_path / "fly.json"
    proc, crews = _two_crews_flying(tmp_path, out)
    _error_after_killing(proc, crews[1][3], "strike")  # the second crew's strike companion dies
    results = json.loads(out.read_text())
    assert "companion strike" in results["error"] and results["episodes"] < 8
    assert not [pid for crew in crews for pid in crew if _alive(pid)]


# ----------------------------------------------------------------------------- bad input


def test_fly_signs_by_default_with_a_key_of_its_own_and_no_signing_turns_it_off() -> None:
    from mavlink_bridge.fly.config import config_from_args

    base = ["--scenario", str(STRIKE), "--pilot", "guidance"]
    assert config_from_args(base).makes_key
    assert not config_from_args([*base, "--no-signing"]).makes_key
    assert not config_from_args([*base, "--no-signing"]).signing
    connect = ["--connect", "udpout:127.0.0.1:1", "udpout:127.0.0.1:2", "udpout:127.0.0.1:3"]
    assert not config_from_args([*base, *connect]).makes_key  # running vehicles: only --signing-key signs


def test_fly_lean_telemetry_is_the_default_in_its_own_lockstep_worlds_and_full_telemetry_keeps_every_stream() -> None:
    from mavlink_bridge.fly.config import config_from_args

    base = ["--scenario", str(STRIKE), "--pilot", "guidance"]
    connect = ["--connect", "udpout:127.0.0.1:1", "udpout:127.0.0.1:2", "udpout:127.0.0.1:3"]
    assert config_from_args(base).lean_telemetry and config_from_args([*base, "--lockstep"]).lean_telemetry
    assert not config_from_args([*base, "--full-telemetry"]).lean_telemetry
    # Real time and running vehicles (a ground station may share their streams): full unless asked.
    assert not config_from_args([*base, "--speedup", "5"]).lean_telemetry
    assert config_from_args([*base, "--speedup", "5", "--lean-telemetry"]).lean_telemetry
    assert not config_from_args([*base, *connect, "--lockstep"]).lean_telemetry
    assert config_from_args([*base, *connect, "--lean-telemetry"]).lean_telemetry
    with pytest.raises(UsageError, match="not allowed with"):
        config_from_args([*base, "--lean-telemetry", "--full-telemetry"])


def test_fly_bad_input_is_one_line_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: strike\nvehicles: {decoy: {speed_min_m_s: fast}}\n")
    cases = [
        (["--scenario", str(STRIKE), "--models", str(tmp_path / "nowhere")], "--pilot guidance"),
        (["--scenario", str(bad), "--pilot", "guidance"], "bad.yaml"),
        (["--scenario", str(STRIKE), "--pilot", "guidance", "--episodes", "0"], "--episodes"),
        (
            [
                "--scenario",
                str(RANDOM),
                "--pilot",
                "guidance",
                "--connect",
                "udpout:127.0.0.1:1",
                "udpout:127.0.0.1:2",
                "udpout:127.0.0.1:3",
            ],
            "fixed layout",
        ),
        (
            [
                "--scenario",
                str(STRIKE),
                "--pilot",
                "guidance",
                "--connect",
                "udpout:127.0.0.1:1",
                "tcp:x:2",
                "udpout:127.0.0.1:3",
            ],
            "udpout:HOST:PORT",
        ),
        (["--scenario", str(STRIKE), "--pilot", "guidance", "--signing-key", str(bad)], "signing key"),
        (["--scenario", str(STRIKE), "--pilot", "guidance", "--speedup", "2", "--lockstep"], "not allowed"),
        (["--scenario", str(STRIKE), "--pilot", "guidance", "--executor", "local", "--address", "h:1"], "executor ray"),
        (["--scenario", str(STRIKE), "--pilot", "guidance", "--no-signing", "--signing-key", str(STRIKE)], "signing"),
        (["--scenario", str(REPO / "scenarios" / "signed.yaml"), "--pilot", "guidance", "--no-signing"], "signing"),
    ]
    empty = tmp_path / "models"
    empty.mkdir()
    (empty / "decoy.pt").write_bytes(b"not a checkpoint")
    cases.append((["--scenario", str(STRIKE), "--models", str(empty)], "--pilot guidance"))
    if not DEFAULT_MODELS.is_dir():
        cases.append((["--scenario", str(STRIKE)], "models directory not found"))
    for argv, needle in cases:
        assert fly.main(argv) == 2, argv
        err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
        assert len(err) == 1 and needle in err[0], (argv, err)
    proc = subprocess.run(
        [sys.executable, "-m", "mavlink_bridge.fly", "--scenario", str(bad), "--pilot", "guidance"],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=_env(),
        timeout=60,
    )
    assert proc.returncode == 2 and proc.stdout == "" and len(proc.stderr.strip().splitlines()) == 1
