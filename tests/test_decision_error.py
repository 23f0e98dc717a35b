"""The batched monitor keeping a companion's error bound (:class:`tssac_core.sim.world_monitor.DecisionError`,
``bench_monitored_team.py --decision-error``): it still decides from the true state, but every decision keeps the
bound's metres off its clearance, so a pilot that steers at a radar is turned away that much farther out."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from benchmarks.bench_monitored_team import main as bench_main
from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.common.cli import run
from tssac_core.sim.adversaries import Adversary, AdversaryPilot
from tssac_core.sim.missions import fly_missions, mission_layout
from tssac_core.sim.scenario import load
from tssac_core.sim.world_monitor import DecisionError

ROOT = Path(__file__).resolve().parent.parent
SEED = 424242


def closest_to_a_radar_m(error: DecisionError | None) -> float:
    """Four random.yaml layouts (eq. 5, 150 s) with every UAV steering at the nearest radar, through the monitor:
    the closest any UAV came to a radar's edge (m)."""
    scenario = dataclasses.replace(load(ROOT / "scenarios" / "random.yaml"), episode_steps=1500)
    layouts = [mission_layout(scenario, SEED, k) for k in range(4)]
    results = fly_missions(
        scenario, [AdversaryPilot(Adversary.AT_RADAR)] * 3, 0, SEED, layouts=layouts, shield=ShieldConfig(),
        record=True, decision_error=error,
    )  # fmt: skip
    assert results.trajectories is not None and results.cost.sum() == 0
    closest = np.inf
    for layout, track in zip(results.layouts, results.trajectories, strict=True):
        for radar in layout.radars:
            cx, cy = (1000.0 * c for c in radar.position_km)
            edge = np.hypot(track[..., 0] - cx, track[..., 1] - cy) - 1000.0 * radar.radius_km
            closest = min(closest, float(np.nanmin(edge)))
    return closest


def test_a_position_error_keeps_a_pilot_steering_at_a_radar_that_much_farther_out() -> None:
    exact = closest_to_a_radar_m(None)
    kept = closest_to_a_radar_m(DecisionError(1500.0, 0.0, 0.0))
    assert 0.0 <= exact < 1000.0  # the true state's monitor lets it come within its margin and the decisions' reach
    assert kept >= exact + 1000.0  # every backup loses the 1,500 m from its clearance (here 122 m -> 1,605 m)


@pytest.mark.parametrize("bad", [(-1.0, 0.0, 0.0), (0.0, float("nan"), 0.0), (0.0, 0.0, float("inf"))])
def test_a_decision_error_is_finite_and_not_negative(bad: tuple[float, float, float]) -> None:
    with pytest.raises(ValueError, match="decision error"):
        DecisionError(*bad)


def test_the_benchmark_refuses_a_bad_decision_error_in_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["--models", str(ROOT / "models" / "tssac"), "--seed", "1", "--decision-error", "1", "-2", "1"]
    assert run(bench_main, argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--decision-error" in err and "heading_rad" in err
