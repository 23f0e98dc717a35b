"""Shared fixtures: scenario paths and small helpers."""

from __future__ import annotations

import compileall
import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ROOT / "scenarios"

# Two test processes share the two cores (pyproject: pytest-xdist -n 2). Each runs torch on one thread, as does
# every process a test starts unless it sets its own count (they inherit the variable): a second OpenMP thread per
# process would only spin against the other test process. Set before any test module imports torch.
os.environ.setdefault("OMP_NUM_THREADS", "1")


def pytest_configure(config: pytest.Config) -> None:
    """Byte-compile the project once, in the controlling process, before any test runs. Where the environment sets
    PYTHONDONTWRITEBYTECODE (this project's machines do), no import writes a .pyc, so each of the about 250 Python
    processes the tests start (fly, worlds, fork servers, training runs, Ray's) would compile the project's source
    again: up to 0.85 s of CPU for all of it. Python still reads the .pyc files compileall writes, and recompiles a
    stale one."""
    if hasattr(config, "workerinput"):  # an xdist worker: its controller has done it
        return
    for package in ("tssac_core", "mavlink_bridge", "sim_vehicles", "benchmarks"):
        compileall.compile_dir(ROOT / package, quiet=1)


OMNISAFE_TESTS = ("test_omnisafe_env.py", "test_crosscheck_omnisafe.py")
"""Tests that import OmniSafe: they run in OmniSafe's own environment (tests/test_omnisafe_side.py runs them there);
in any other they are not collected, rather than skipped."""
try:
    import omnisafe  # noqa: F401
except ImportError:
    collect_ignore = list(OMNISAFE_TESTS)


@pytest.fixture(scope="session")
def strike_path() -> Path:
    return SCENARIOS / "strike.yaml"


@pytest.fixture(scope="session")
def random_path() -> Path:
    return SCENARIOS / "random.yaml"
