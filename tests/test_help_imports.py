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
    description = done.stdout.split("\n\n")[1]  # after the usage block, before the arguments
    assert not description.rstrip().endswith(":"), f"{module} --help has no description"
    assert description.rstrip().endswith("."), f"{module} --help's description is cut: {description!r}"
    assert "``" not in description


def test_every_description_taken_from_a_docstring_is_its_whole_first_paragraph():
    """The scripts and commands whose ``--help`` says their docstring's first paragraph (command_description): it ends
    a sentence. The first line alone cut ``experiments --help`` mid-sentence."""
    import ast
    from pathlib import Path

    from tssac_core.common.cli import command_description

    root = Path(__file__).resolve().parent.parent
    users = [
        path
        for folder in ("tssac_core", "mavlink_bridge", "sim_vehicles", "benchmarks")
        for path in sorted((root / folder).rglob("*.py"))
        if "command_description(__doc__)" in path.read_text()
    ]
    assert len(users) >= 20
    for path in users:
        text = command_description(ast.get_docstring(ast.parse(path.read_text()), clean=False))
        assert text.endswith((".", ".)")), f"{path.relative_to(root)}: {text!r}"
    assert command_description("``x``: a first line\nand its second.\n\nMore.") == "x: a first line and its second."
    assert "__doc__.split" not in "".join(p.read_text() for p in users)


def test_the_probe_sees_a_heavy_import():
    """The check above can fail: a module that imports torch at the top is caught."""
    code = "import sys; import tssac_core.deploy.policy; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120).stdout
    assert out.strip() == "True"
