"""Every command answers ``--help`` before it loads torch, gymnasium, Ray, matplotlib, onnxruntime or the filter's
scipy: the heavy imports come after argparse (issue 42). Checked on what the process imported, not on a clock."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("torch", "gymnasium", "ray", "matplotlib", "filterpy", "scipy", "tensorboard", "onnx", "onnxruntime")

COMMANDS = [
    "tssac_core.train",
    "tssac_core.evaluate",
    "tssac_core.experiments",
    "tssac_core.experiments.targets",
    "tssac_core.deploy.export",
    "mavlink_bridge.fly",
    "mavlink_bridge.companion",
    "sim_vehicles",
]

PROBE = """
import json, runpy, sys
sys.argv = [sys.argv[1], "--help"]
try:
    runpy.run_module(sys.argv[0], run_name="__main__", alter_sys=True)
except SystemExit as exc:
    code = exc.code
else:
    code = None
heavy = sorted(name for name in {heavy!r} if name in sys.modules)
print(json.dumps({{"code": code, "heavy": heavy}}), file=sys.stderr)
"""


@pytest.mark.parametrize("module", COMMANDS)
def test_help_loads_no_heavy_package(module):
    done = subprocess.run(
        [sys.executable, "-c", PROBE.format(heavy=HEAVY), module], capture_output=True, text=True, timeout=120
    )
    report = json.loads(done.stderr.strip().splitlines()[-1])
    assert report["code"] in (0, None), done.stderr
    assert "usage:" in done.stdout
    assert report["heavy"] == [], f"{module} --help imported {report['heavy']}"


def test_the_probe_sees_a_heavy_import():
    """The check above can fail: a module that imports torch at the top is caught."""
    code = "import sys; import tssac_core.deploy.policy; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120).stdout
    assert out.strip() == "True"
