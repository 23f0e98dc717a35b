"""The monitor's adjusted action (``ShieldConfig.adjust``, ``--shield-adjust``): a failing proposal gets the passing
candidate nearest it before the backup takes over. Every candidate passes the same check as a proposal, so the
guarantee is the same: these tests fly it where the backup would take over, against a brute-force search of the
candidates, with the adversaries on eq. 5 and on varied F-16 airframes, and over SITL; each with the plain monitor
beside it (the negative control: it engages the backup where the adjusted one does not)."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from sitl_helpers import kept_out

from tssac_core.assurance.monitor import (
    Hazards,
    Limits,
    Memory,
    ShieldConfig,
    adjusted_candidates,
    constant_rollout,
    decide,
)
from tssac_core.sim.adversaries import Adversary, AdversaryPilot
from tssac_core.sim.airframe_response import load_response
from tssac_core.sim.missions import fly_missions, mission_layout
from tssac_core.sim.scenario import dump, load
from tssac_core.sim.varied_airframes import AirframeVariation

REPO = Path(__file__).resolve().parents[1]
HZ = Hazards(np.array([[[50_000.0, 50_000.0]]]), np.array([[12_000.0]]), 100_000.0)
LIM = Limits(np.array([150.0]), np.array([300.0]), np.radians([5.0]), np.array([10.0]))
DT, STEPS = 0.1, 10


def head_on(cfg: ShieldConfig, decisions: int = 150) -> list[tuple[np.ndarray, object]]:
    """Straight at a radar at full speed, the proposal [0, 1] every second: each decision's state and what it gave;
    the flown path keeps the margin at every step."""
    mem, state, out = Memory.initial(1), np.array([[20_000.0, 50_000.0, 300.0, 0.0]]), []
    for _ in range(decisions):
        d = decide(state, np.array([[0.0, 1.0]]), mem, HZ, LIM, DT, STEPS, cfg.margin_m, cfg)
        out.append((state, d))
        mem = d.memory
        xs, ys, vs, ps = constant_rollout(*state.T, d.action, LIM, DT, STEPS)
        gaps = np.hypot(xs - 50_000.0, ys - 50_000.0) - 12_000.0
        assert gaps.min() >= cfg.margin_m
        state = np.array([[xs[0, -1], ys[0, -1], vs[0, -1], ps[0, -1]]])
    return out


def passing_candidates(state: np.ndarray, memory: Memory) -> list[np.ndarray]:
    """The candidates for the proposal [0, 1] that pass when each is checked on its own, as a proposal is."""
    cfg = ShieldConfig()
    candidates = adjusted_candidates(np.array([[0.0, 1.0]]))[0]
    return [c for c in candidates if not decide(state, c[None, :], memory, HZ, LIM, DT, STEPS, 100.0, cfg).engaged[0]]


def test_head_on_the_adjusted_monitor_flies_the_nearest_passing_action_and_the_backup_only_when_none_passes():
    adjusted = head_on(ShieldConfig(adjust=True))
    plain = head_on(ShieldConfig())
    first_plain = next(k for k, (_, d) in enumerate(plain) if d.engaged[0])
    assert not any(d.adjusted[0] for _, d in plain)  # the negative control: the plain monitor engages its backup
    assert not any(d.engaged[0] for _, d in adjusted[: first_plain + 1])  # ... where the adjusted one turns away
    memory = Memory.initial(1)
    for state, d in adjusted:
        if d.adjusted[0] or d.engaged_now[0]:
            passing = passing_candidates(state, memory)
            if d.engaged_now[0]:
                assert not passing  # the backup takes over only when no candidate passes
            else:
                nearest = min(passing, key=lambda c: abs(c[0]) + abs(c[1] - 1.0) / 2)
                assert np.allclose(d.action[0], nearest) and not np.allclose(d.action[0], [0.0, 1.0])
        memory = d.memory
    assert sum(d.adjusted[0] for _, d in adjusted) >= 5
    assert sum(d.engaged[0] for _, d in adjusted) < sum(d.engaged[0] for _, d in plain)


def test_a_flying_backup_goes_back_to_the_proposal_alone():
    """Engaged, a failing proposal is not adjusted: the backup flies on (the release rule is the proposal's)."""
    cfg = ShieldConfig(adjust=True)
    engaged = Memory(
        np.array([True]), np.array([True]), np.array([1]), np.array([0]), np.array([0]), np.full(1, np.nan)
    )
    state = np.array([[36_000.0, 50_000.0, 300.0, 0.0]])  # 2 km from the disk, heading at it
    d = decide(state, np.array([[0.0, 1.0]]), engaged, HZ, LIM, DT, STEPS, cfg.margin_m, cfg)
    assert d.engaged[0] and not d.adjusted[0]
    assert np.allclose(d.action[0], [-1.0, 0.0])  # backup 1: the right turn at constant speed


def test_a_non_finite_proposal_is_never_adjusted():
    cfg = ShieldConfig(adjust=True)
    state = np.array([[30_000.0, 50_000.0, 300.0, 0.0]])
    d = decide(state, np.array([[math.nan, 0.0]]), Memory.initial(1), HZ, LIM, DT, STEPS, cfg.margin_m, cfg)
    assert d.engaged[0] and not d.adjusted[0]


def test_the_candidates_are_the_proposals_turn_and_the_grid_at_its_acceleration_constant_speed_and_braking():
    c = adjusted_candidates(np.array([[0.3, 0.6]]))[0]
    assert c.shape == (30, 2)
    expected = {(0.3, 0.6), (0.3, 0.0), (0.3, -1.0), (-1.0, 0.6), (1.0, -1.0), (0.25, 0.0)}
    assert {tuple(np.round(a, 3)) for a in c} >= expected


# --------------------------------------------------------------------------------- the batched world

LAYOUT_SEED = 4_410_000
"""random.yaml's layouts of this seed (this file's own range)."""


@pytest.mark.parametrize("varied", [False, True], ids=["eq5", "f16-airframes"])
@pytest.mark.parametrize("adversary", [Adversary.AT_RADAR, Adversary.FULL_SPEED], ids=str)
def test_adversaries_through_the_adjusted_monitor_stay_out(adversary: Adversary, varied: bool) -> None:
    from sim_vehicles.dynamics.response_fit import response_path

    scenario = dataclasses.replace(load(REPO / "scenarios" / "random.yaml"), episode_steps=1500)
    layouts = [mission_layout(scenario, LAYOUT_SEED, k) for k in range(8)]
    variation = AirframeVariation.from_response(load_response(response_path("f16"))) if varied else None
    flown = {
        adjust: fly_missions(
            scenario,
            [AdversaryPilot(adversary)] * 3,
            0,
            LAYOUT_SEED,
            layouts=layouts,
            shield=ShieldConfig(adjust=adjust),
            airframes=variation,
        )  # fmt: skip
        for adjust in (False, True)
    }
    for results in flown.values():
        assert results.monitor is not None
        assert results.cost.max() == 0.0 and not results.out_of_area.any()
        assert results.monitor.unprotected_steps.sum() == 0
    adjusted, plain = flown[True].monitor, flown[False].monitor
    assert adjusted is not None and plain is not None
    assert adjusted.adjusted_steps.sum() > 0 and plain.adjusted_steps.sum() == 0


# --------------------------------------------------------------------------------- the command line and SITL


def fly(args: list[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mavlink_bridge.fly", *args, "--lockstep", "--no-progress"],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        timeout=580,
    )


def test_shield_adjust_without_the_shield_is_one_line_and_exit_2():
    proc = fly(["--scenario", str(REPO / "scenarios" / "strike.yaml"), "--shield-adjust"])
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "python -m mavlink_bridge.fly: error: --shield-adjust changes what the monitor flies: it needs --shield"
    ]


@pytest.mark.sitl
@pytest.mark.timeout(600)
def test_a_straight_pilot_into_a_radar_is_turned_by_adjusted_actions_over_sitl(tmp_path: Path) -> None:
    # The strike mission's three UAVs start heading straight at the radar at (38, 44) km; 150 s suffice.
    scenario = dataclasses.replace(load(REPO / "scenarios" / "strike.yaml"), episode_steps=1500)
    path = tmp_path / "straight.yaml"
    dump(scenario, path)
    out = tmp_path / "fly.json"
    proc = fly(["--scenario", str(path), "--pilot", "straight", "--shield", "--shield-adjust", "--json", str(out)])
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "adjusted" in proc.stdout
    mission, shield = kept_out(json.loads(out.read_text()))
    assert shield["adjusted_time_fraction"] > 0
    counts = [c["shield"] for c in mission["companions"].values()]
    assert all(c["adjusted_steps"] > 0 for c in counts), counts


def test_evaluate_reports_the_adjusted_share(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from tssac_core.evaluate import main

    path = tmp_path / "strike60.yaml"
    dump(dataclasses.replace(load(REPO / "scenarios" / "strike.yaml"), episode_steps=600), path)
    argv = ["--controller", "at_radar", "--scenario", str(path), "--episodes", "2", "--seed", "1", "--no-progress"]
    assert main([*argv, "--shield", "--shield-adjust"]) == 0
    line = next(t for t in capsys.readouterr().out.splitlines() if t.startswith("shield:"))
    assert "% adjusted" in line and "0 UAV-missions with cost" in line
    assert main([*argv, "--shield"]) == 0
    line = next(t for t in capsys.readouterr().out.splitlines() if t.startswith("shield:"))
    assert "adjusted" not in line
