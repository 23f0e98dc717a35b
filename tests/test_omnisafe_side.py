"""The OmniSafe adapter's and the cross-check's OmniSafe tests, run by the test command in OmniSafe's own environment.

OmniSafe 0.5.0 pins gymnasium 0.28.1 and this project needs gymnasium >= 1.0, so tests/test_omnisafe_env.py and
tests/test_crosscheck_omnisafe.py cannot run in the main environment (tests/conftest.py leaves them out of its
collection: nothing is skipped). Here they run in OmniSafe's environment, which benchmarks/omnisafe_env.py builds
once per machine (kept in ~/.cache/tssac; on a fresh machine about 1.5 min of CPU) and reuses; every one of them must
pass, none may be skipped.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from conftest import OMNISAFE_TESTS  # noqa: E402

from benchmarks.omnisafe_env import BuildFailed, omnisafe_python, writing_bytecode  # noqa: E402

# Its own group: the build is mostly downloads and unpacking, which overlap the other worker's tests.
pytestmark = pytest.mark.xdist_group("omnisafe")


@pytest.mark.slow
@pytest.mark.timeout(1200)  # a first build on a busy machine took up to 12 minutes
def test_omnisafe_tests_pass_in_omnisafes_environment() -> None:
    try:
        python = omnisafe_python()
    except BuildFailed as exc:
        pytest.fail(str(exc))
    # Bytecode written: an environment built before its build kept the bytecode of its imports gets it on this run.
    env = {**writing_bytecode(), "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    files = [str(ROOT / "tests" / name) for name in OMNISAFE_TESTS]
    done = subprocess.run(
        [str(python), "-m", "pytest", "-q", "-o", "addopts=", "-p", "no:cacheprovider", "-rs", *files],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    tail = done.stdout.strip().splitlines()[-1] if done.stdout.strip() else done.stderr.strip()
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    outcomes = r"(\d+) (passed|failed|skipped|errors?|deselected|xfailed|xpassed)"
    counts = {kind: int(n) for n, kind in re.findall(outcomes, tail)}
    assert set(counts) == {"passed"} and counts["passed"] >= 14, tail  # nothing skipped, failed or deselected
