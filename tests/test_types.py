"""The type check, mypy on the three packages as pyproject.toml configures it (``[tool.mypy]``), run as a test: it
starts first (tests/conftest.py puts it at the head of the collection) and runs beside the other tests, on the time
their waits leave free (SITL missions paced by real clocks, serial lines, processes starting), instead of before them.
Any type error fails it, with mypy's report."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.xdist_group("mypy")


@pytest.mark.timeout(900)
def test_the_three_packages_type_check() -> None:
    done = subprocess.run([sys.executable, "-m", "mypy"], cwd=ROOT, capture_output=True, text=True, timeout=850)
    assert done.returncode == 0, (done.stdout + done.stderr)[-8000:]
    assert done.stdout.strip().splitlines()[-1].startswith("Success: no issues found"), done.stdout[-2000:]
