"""The README's "Evaluating and flying any policy": its two blocks run as they stand there (read from the README, not
copied): Stable-Baselines3 trains a PPO decoy, the evaluator measures it beside the shipped detect and strike UAVs from
Python and from the command line (the same figures), and the three fly over MAVLink as ONNX actors behind --shield."""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tssac_core.deploy.onnx_actor import OnnxPolicy

REPO = Path(__file__).resolve().parent.parent
HEADING = "### Evaluating and flying any policy"


def readme_blocks() -> tuple[str, str]:
    """The section's first python block and first bash block, as written."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    section = text[text.index(HEADING) :]
    section = section[: section.index("\n## ")]
    python = re.search(r"```python\n(.*?)```", section, re.S)
    bash = re.search(r"```bash\n(.*?)```", section, re.S)
    assert python is not None and bash is not None
    return python.group(1), bash.group(1)


def test_the_blocks_are_found_and_say_what_the_test_checks():
    python, bash = readme_blocks()
    assert "from_sb3(" in python and "evaluate_policy(" in python and "export_team(" in python
    lines = [ln for ln in bash.splitlines() if ln.strip()]
    assert [ln.split()[:3] for ln in lines] == [
        ["python", "-m", "tssac_core.evaluate"],
        ["python", "-m", "mavlink_bridge.fly"],
    ]
    assert "--shield" in lines[1] and "--models ppo-team" in lines[1]


@pytest.mark.slow
@pytest.mark.sitl
@pytest.mark.timeout(400)
def test_the_readme_sb3_snippet_trains_evaluates_and_flies_over_mavlink(tmp_path: Path):
    python, bash = readme_blocks()
    for name in ("models", "scenarios"):  # the snippet's relative paths, read only; what it writes stays in tmp_path
        (tmp_path / name).symlink_to(REPO / name)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    t0 = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-c", python], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-3000:]
    t_python = time.monotonic() - t0
    ours = json.loads((tmp_path / "ppo-decoy.json").read_text())
    assert ours["episodes"] == 2 and set(ours["roles"]) == {"decoy", "detect", "strike"}
    stated = {"policy": "ppo-decoy.zip", "observation": "route", "decision_interval_s": 1.0}  # read from the env
    assert ours["policies"] == {"decoy": stated}
    assert ours["controller"] == "decoy=ppo-decoy.zip, others=models/tssac"
    printed = done.stdout.split()
    assert printed[:2] == [repr(ours["success_rate"]), repr(ours["mean_cost"])]
    team = tmp_path / "ppo-team"
    decoy = OnnxPolicy.load(team / "decoy.onnx", "decoy")
    assert decoy.meta["source"] == "ppo-decoy.zip" and decoy.action_repeat == 10
    assert OnnxPolicy.load(team / "strike.onnx", "strike").meta["source"] == "strike.npz"

    evaluate, fly = (shlex.split(line) for line in bash.splitlines() if line.strip())
    for argv in (evaluate, fly):
        t0 = time.monotonic()
        done = subprocess.run(
            [sys.executable, *argv[1:], "--no-progress"],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert done.returncode == 0, (argv[2], done.stderr[-3000:])
        print(f"{argv[2]}: {time.monotonic() - t0:.1f} s wall")
    cli = json.loads((tmp_path / "ppo-decoy-cli.json").read_text())
    assert cli == ours  # the command line's evaluation is the Python one: every figure, interval and key

    flown = json.loads((tmp_path / "ppo-fly.json").read_text())
    mission = flown["missions"][0]
    assert flown["pilot"] == str(team.resolve()) and flown["episodes"] == 1
    assert "shield" in flown and mission["steps"] > 0
    assert all(c["exit_code"] == 0 for c in mission["companions"].values()), mission["companions"]
    # The monitor held the untrained decoy (and the others) clear: no hazard cost, nobody left the area.
    assert flown["mean_cost"] == 0.0 and flown["shield"]["uavs_left_area"] == 0
    print(f"README snippet: training, evaluation and export {t_python:.1f} s wall")
