"""The console scripts of pyproject's [project.scripts] (issue 62): each names a callable that runs as its
``python -m`` form does. Read from pyproject itself: an editable install sees a new script only once reinstalled."""

from __future__ import annotations

import importlib
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCRIPTS = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
MODULES = {
    "tssac-train": "tssac_core.train",
    "tssac-evaluate": "tssac_core.evaluate",
    "tssac-fly": "mavlink_bridge.fly",
    "tssac-sitl": "sim_vehicles",
}
# What the installed script runs: its target called with no arguments, its return value the exit code.
SCRIPT = (
    "import importlib, sys; m, _, f = sys.argv[1].partition(':'); sys.argv = sys.argv[2:]; "
    "sys.exit(getattr(importlib.import_module(m), f)())"
)


def _target(name: str):
    module, _, attr = SCRIPTS[name].partition(":")
    return getattr(importlib.import_module(module), attr)


def test_every_command_has_its_script():
    assert sorted(SCRIPTS) == sorted(MODULES)
    for name in SCRIPTS:
        assert callable(_target(name)), name


@pytest.mark.parametrize("name", sorted(MODULES))
def test_a_script_answers_help_as_its_module_does(name):
    def run(argv: list[str]) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, *argv], capture_output=True, text=True, timeout=120, cwd=ROOT)

    script = run(["-c", SCRIPT, SCRIPTS[name], name, "--help"])
    module = run(["-m", MODULES[name], "--help"])
    assert script.returncode == module.returncode == 0, script.stderr
    assert script.stdout == module.stdout and "usage:" in script.stdout


def test_a_script_reports_bad_input_as_its_module_does():
    """The one-line error and exit code 2 of ``python -m tssac_core.evaluate`` (its ``run`` wrapper), not a trace."""
    argv = ["--scenario", "no-such-scenario.yaml", "--episodes", "1", "--no-progress"]
    script = subprocess.run(
        [sys.executable, "-c", SCRIPT, SCRIPTS["tssac-evaluate"], "tssac-evaluate", *argv],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    module = subprocess.run(
        [sys.executable, "-m", "tssac_core.evaluate", *argv], capture_output=True, text=True, timeout=120, cwd=ROOT
    )
    assert script.returncode == module.returncode == 2
    assert script.stderr == module.stderr and "Traceback" not in script.stderr
