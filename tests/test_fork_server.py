"""The fork server: a program forked from a warm interpreter behaves as ``python -m`` started afresh would (its output,
its exit status, its session), is stopped like any child, and never outlives its server
(mavlink_bridge.processes.fork_server)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from mavlink_bridge.processes.children import ChildProcesses
from mavlink_bridge.processes.fork_server import ForkServer, ForkServerError

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sitl_helpers import parent_pid, running  # noqa: E402

DOCUMENT = {"b": [1, 2.5, None], "a": "ü", "c": {"z": True}}


@pytest.fixture
def server(tmp_path: Path) -> Iterator[ForkServer]:
    children = ChildProcesses(grace_s=5.0)
    forks = ForkServer(children, ["json.tool"], log_path=tmp_path / "server.log", env=dict(os.environ))
    try:
        yield forks
    finally:
        forks.close()
        children.stop_all()


def test_a_forked_program_prints_and_exits_as_python_m_does(server: ForkServer, tmp_path: Path) -> None:
    text = json.dumps(DOCUMENT).encode()
    fresh = subprocess.run(
        [sys.executable, "-m", "json.tool", "--sort-keys"], input=text, capture_output=True, timeout=60
    )
    child = server.start(
        "tool", "json.tool", ["--sort-keys"], log_path=tmp_path / "tool.log", stdin_pipe=True, stdout_pipe=True
    )
    assert child.process.stdin is not None and child.process.stdout is not None
    assert os.getsid(child.pid) == child.pid  # it leads its own session: stopped by process group
    assert parent_pid(child.pid) == server.child.pid
    child.process.stdin.write(text)
    child.process.stdin.close()
    assert child.process.stdout.read() == fresh.stdout
    assert child.process.wait(30) == fresh.returncode == 0
    assert child.poll() == 0
    # Bad input: the same exit status, and the message that python -m prints on stderr goes to the log.
    bad = subprocess.run([sys.executable, "-m", "json.tool"], input=b"{nope", capture_output=True, timeout=60)
    child = server.start("bad", "json.tool", [], log_path=tmp_path / "bad.log", stdin_pipe=True)
    assert child.process.stdin is not None
    child.process.stdin.write(b"{nope")
    child.process.stdin.close()
    assert child.process.wait(30) == bad.returncode == 1
    assert (tmp_path / "bad.log").read_bytes() == bad.stderr


def test_a_program_that_cannot_run_exits_1_with_the_reason_in_its_log(server: ForkServer, tmp_path: Path) -> None:
    child = server.start("none", "no_such_module_here", [], log_path=tmp_path / "none.log")
    assert child.process.wait(30) == 1
    assert "No module named" in (tmp_path / "none.log").read_text()
    (tmp_path / "a-file").write_text("")
    with pytest.raises(ForkServerError, match="cannot start"):  # its log cannot be opened: nothing was forked
        server.start("nolog", "json.tool", [], log_path=tmp_path / "a-file" / "x.log", timeout_s=30)
    assert server.alive


def test_a_running_program_times_out_then_reports_the_signal_that_stopped_it(
    server: ForkServer, tmp_path: Path
) -> None:
    child = server.start("waits", "json.tool", [], log_path=None, stdin_pipe=True)  # reads until its input ends
    with pytest.raises(subprocess.TimeoutExpired):
        child.process.wait(0.3)
    assert child.poll() is None and running(child.pid)
    server.children.stop([child], grace_s=5.0)  # SIGTERM to its process group, as every child is stopped
    assert child.poll() == -signal.SIGTERM
    assert not running(child.pid)


def test_programs_die_with_their_server_and_a_closed_server_stops_them(tmp_path: Path) -> None:
    for ending in ("killed", "closed"):
        children = ChildProcesses(grace_s=5.0)
        forks = ForkServer(children, [], log_path=tmp_path / f"{ending}.log", env=dict(os.environ))
        try:
            child = forks.start("waits", "json.tool", [], log_path=None, stdin_pipe=True)
            assert child.poll() is None
            if ending == "killed":
                os.kill(forks.child.pid, signal.SIGKILL)  # no clean-up at all: the parent-death signal
            else:
                forks.close()
            deadline = time.monotonic() + 10.0
            while running(child.pid) and time.monotonic() < deadline:
                time.sleep(0.02)
            assert not running(child.pid), ending
            assert child.process.wait(10) == -signal.SIGTERM
            assert not forks.alive
            with pytest.raises(ForkServerError):
                forks.start("late", "json.tool", [], log_path=None, timeout_s=5)
        finally:
            forks.close()
            children.stop_all()


SLOW_EXIT = """
import signal, sys, time
signal.signal(signal.SIGTERM, lambda *_: (time.sleep(0.5), sys.exit(0)))
print("ready", flush=True)
while True:
    time.sleep(0.05)
"""


def test_programs_of_a_killed_server_are_waited_for_not_reported_as_surviving_sigkill(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """``kill -9`` of the server: its programs take a moment to end (the parent-death SIGTERM); stopping them waits
    for that, with no false "did not stop" or "survived SIGKILL" line."""
    (tmp_path / "slow_exit.py").write_text(SLOW_EXIT)
    children = ChildProcesses(grace_s=5.0)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]))
    forks = ForkServer(children, [], log_path=tmp_path / "server.log", env=env)
    try:
        programs = [forks.start(f"slow{i}", "slow_exit", [], log_path=None, stdout_pipe=True) for i in range(3)]
        for program in programs:
            assert program.process.stdout is not None and program.process.stdout.readline() == b"ready\n"
        os.kill(forks.child.pid, signal.SIGKILL)
        forks.child.process.wait(10)
        with caplog.at_level("WARNING", logger="mavlink_bridge.processes.children"):
            children.stop(programs)
        assert not caplog.records, [r.getMessage() for r in caplog.records]
        assert [p.poll() for p in programs] == [-signal.SIGTERM] * 3
        assert not [p.pid for p in programs if running(p.pid)]
    finally:
        forks.close()
        children.stop_all()


def test_a_server_that_cannot_import_its_preload_is_one_clear_error(tmp_path: Path) -> None:
    children = ChildProcesses(grace_s=5.0)
    forks = ForkServer(children, ["no_such_module_here"], log_path=tmp_path / "server.log", env=dict(os.environ))
    try:
        with pytest.raises(ForkServerError, match=r"the fork server \(pid \d+\) (has )?ended"):
            forks.start("world", "json.tool", [], log_path=None, timeout_s=60)
        assert not forks.alive
        assert "No module named 'no_such_module_here'" in (tmp_path / "server.log").read_text()
    finally:
        forks.close()
        children.stop_all()
