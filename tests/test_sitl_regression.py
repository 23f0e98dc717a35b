"""SITL regression tests: the shipped models fly every scenario that has an ``expect:`` block.

Each scenario's missions are flown end to end by ``python -m mavlink_bridge.fly`` in lockstep (a degraded
link's latency and loss in simulated time too; or at the ``expect.speedup`` a scenario names): the bundled SITL world,
one companion process per UAV (Kalman filter, observation, policy, setpoints over MAVLink), scored
from the world's truth log. The layouts come from seeds training never drew from
(training seeds its layout generators with 0-2; these start at 7001). A failure prints the
per-mission table.

    pytest -m sitl            # just these (CI's tier: -m 'sitl and not slow')
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tssac_core.sim.scenario import load

REPO = Path(__file__).resolve().parents[1]
MODELS = REPO / "models" / "tssac"
EVAL_SEED = 7001
SCENARIOS = sorted(p for p in (REPO / "scenarios").glob("*.yaml") if load(p).expect is not None)
CI_TIER = {"strike", "signed"}
"""The scenarios CI flies (a minute of CPU between them); the campaigns of the others take minutes each and fly in the
slow tier (``pytest -m slow``)."""


def table(summary: dict) -> str:
    lines = ["mission  success  time_s  " + "  ".join(f"cost_{r:6s}" for r in ("decoy", "detect", "strike"))]
    for i, m in enumerate(summary.get("missions", [])):
        costs = m.get("cost") or {}
        lines.append(
            f"{i:7d}  {str(bool(m.get('success'))):7s}  {m.get('sim_time_s', float('nan')):6.1f}  "
            + "  ".join(f"{costs.get(r, float('nan')):11.1f}" for r in ("decoy", "detect", "strike"))
        )
    return "\n".join(lines)


@pytest.mark.sitl
@pytest.mark.timeout(900)
@pytest.mark.parametrize(
    "scenario", [pytest.param(p, id=p.stem, marks=() if p.stem in CI_TIER else pytest.mark.slow) for p in SCENARIOS]
)
def test_shipped_models_meet_the_scenario_expectations(scenario: Path, tmp_path: Path) -> None:
    expect = load(scenario).expect
    assert expect is not None
    out = tmp_path / "fly.json"
    clock = ["--lockstep"] if expect.speedup is None else ["--speedup", str(expect.speedup)]
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "mavlink_bridge.fly",
            "--scenario",
            str(scenario),
            "--models",
            str(MODELS),
            "--episodes",
            str(expect.episodes),
            "--seed",
            str(EVAL_SEED),
            *clock,
            "--json",
            str(out),
            "--no-progress",
        ],
        capture_output=True,
        text=True,
        timeout=880,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads(out.read_text())
    report = (
        f"\n{scenario.name}: success {summary['success_rate']:.0%} {summary['success_interval95']}, mean cost "
        f"{summary['mean_cost']:.2f} {summary['mean_cost_interval95']}\n{table(summary)}"
    )
    assert summary["episodes"] == expect.episodes, report
    assert summary["success_rate"] >= expect.min_success_rate, report
    assert summary["mean_cost"] <= expect.max_mean_cost, report
    assert summary["success_interval95"][0] >= expect.min_success_low95, report
    if expect.max_cost_high95 is not None:
        assert summary["mean_cost_interval95"][1] <= expect.max_cost_high95, report
