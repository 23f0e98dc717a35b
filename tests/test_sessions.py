"""A nice command's workers stay nice in their own sessions (tssac_core/common/sessions.py): the fork server's
programs, fly's children and the experiments' training jobs each start a session, which Linux's autogroup scheduling
gives a group of its own at nice 0 unless the process says otherwise."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

from tssac_core.common.sessions import keep_nice_in_new_session

REPO = Path(__file__).resolve().parents[1]
AUTOGROUPS = Path("/proc/sys/kernel/sched_autogroup_enabled")
IMPORT = "from tssac_core.common.sessions import keep_nice_in_new_session"


def run_niced(nice: int, code: str) -> str:
    """``code`` run by a Python started under ``nice -n nice``; its stdout."""
    done = subprocess.run(
        ["nice", "-n", str(nice), sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def test_the_process_nice_value_is_written_to_its_autogroup_only_when_above_zero(tmp_path: Path) -> None:
    for nice, expected in ((7, "7"), (0, None)):
        group = tmp_path / f"autogroup-{nice}"
        run_niced(nice, f"from pathlib import Path\n{IMPORT}\nkeep_nice_in_new_session(Path({str(group)!r}))")
        assert (group.read_text() if group.exists() else None) == expected
    keep_nice_in_new_session(tmp_path / "no" / "such" / "file")  # no autogroups here: nothing, no error


def test_children_and_forked_programs_keep_the_nice_value_of_the_command() -> None:
    """Under ``nice -n 6``: a child of :class:`ChildProcesses` and a program of the fork server, each the leader of a
    session of its own, run in an autogroup at nice 6 (before, at 0)."""
    assert AUTOGROUPS.read_text().strip() == "1", "this test needs a kernel with autogroup scheduling on"
    out = run_niced(
        6,
        """
        import os, sys
        from pathlib import Path
        from mavlink_bridge.processes.children import ChildProcesses
        from mavlink_bridge.processes.fork_server import ForkServer

        children = ChildProcesses(grace_s=1.0)
        sleeper = children.start("sleeper", [sys.executable, "-c", "import time; time.sleep(30)"])
        server = ForkServer(children, ["timeit"], log_path=None, env=dict(os.environ))
        forked = server.start("forked", "timeit", ["-n", "1", "import time; time.sleep(30)"], log_path=None)
        for child in (sleeper, forked):
            assert os.getsid(child.pid) == child.pid  # a session of its own
            print(Path(f"/proc/{child.pid}/autogroup").read_text().split()[-1])
        children.stop_all()
        """,
    )
    assert out.split() == ["6", "6"]
