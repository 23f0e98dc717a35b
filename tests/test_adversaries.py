"""Adversarial pilots (tssac_core/sim/adversaries.py): each acts as its table says, the companion's pilot decides as
the batched world's does, and in the batched world none of them gets a UAV into a radar or out of the area while
the runtime-assurance monitor is on, though every one of them does so without it."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

from mavlink_bridge.companion.cli import build_companion
from mavlink_bridge.companion.config import PILOT_NAMES, CompanionConfig
from mavlink_bridge.companion.held_pilot import HeldPilot
from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.sim.adversaries import (
    DECISION_STEPS,
    Adversary,
    AdversaryPilot,
    Situation,
    adversary_actions,
    layout_keys,
)
from tssac_core.sim.missions import MissionResults, fly_missions, mission_layout
from tssac_core.sim.scenario import ROLES, Layout, Role, Scenario, dump, load
from tssac_core.sim.world import World
from tssac_core.sim.world_state import initial_state, snapshot

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
SEED = 2_100_001
"""Layouts of seeds 2,100,001+ (the adversaries' own range, used for nothing else)."""
STEPS = 1500
"""150 s: unmonitored, 91-100% of random.yaml's missions have met a radar by then (all but the turns)."""
RANDOM_LAYOUTS = 60
CORNER_LAYOUTS = 20
"""Layouts per adversary (x 3 UAVs each): the monitor's decisions are most of the time (about 10 s per adversary
on one core); benchmarks/bench_adversaries.py flies thousands."""


def one_uav(x_km: float, y_km: float, heading_deg: float, radars: Sequence[tuple[float, float, float]]) -> Situation:
    """A situation of one UAV (shape (1,)) in a 100 km area with these radars (x, y, radius in km)."""
    r = np.array(radars, dtype=np.float64).reshape(-1, 3) * 1000.0
    return Situation(
        x_m=np.array([x_km * 1000.0]),
        y_m=np.array([y_km * 1000.0]),
        phi_rad=np.array([math.radians(heading_deg)]),
        decision=np.array([0]),
        key=np.array([12345], dtype=np.uint64),
        radar_m=r[None, :, :2],
        radar_r_m=r[None, :, 2],
        turn_per_decision_rad=np.array([math.radians(5.0)]),
        area_m=100_000.0,
    )


def test_the_fixed_pilots_act_as_their_table_says():
    s = one_uav(50, 50, 0, [(80, 50, 12)])
    assert adversary_actions(Adversary.FULL_SPEED, s).tolist() == [[0.0, 1.0]]
    assert adversary_actions(Adversary.TURN_LEFT, s).tolist() == [[1.0, 1.0]]
    assert adversary_actions(Adversary.TURN_RIGHT, s).tolist() == [[-1.0, 1.0]]
    assert np.isnan(adversary_actions(Adversary.NAN, s)).all()
    chatter = [
        adversary_actions(Adversary.CHATTER, dataclasses.replace(s, decision=np.array([d])))[0].tolist()
        for d in range(4)
    ]
    assert chatter == [[1.0, 1.0], [-1.0, -1.0], [1.0, 1.0], [-1.0, -1.0]]


def test_at_radar_turns_at_full_rate_towards_the_nearest_disk_then_points_at_its_centre():
    # North at 20 km (its disk 8 km away) is nearer than east at 15 km with a 3 km radius (12 km away).
    radars = [(65, 50, 3), (50, 70, 12)]
    assert adversary_actions(Adversary.AT_RADAR, one_uav(50, 50, 0, radars)).tolist() == [[1.0, 1.0]]
    assert adversary_actions(Adversary.AT_RADAR, one_uav(50, 50, 180, radars)).tolist() == [[-1.0, 1.0]]
    assert adversary_actions(Adversary.AT_RADAR, one_uav(50, 50, 90, radars)).tolist() == [[0.0, 1.0]]
    # 2 deg off the bearing: less than one decision's 5 deg, so the turn takes out just the error.
    omega = adversary_actions(Adversary.AT_RADAR, one_uav(50, 50, 88, radars))[0, 0]
    assert omega == pytest.approx(2.0 / 5.0)
    # Unused radar slots (radius 0) are no aim: without a radar it flies on.
    assert adversary_actions(Adversary.AT_RADAR, one_uav(50, 50, 30, [(60, 50, 0)])).tolist() == [[0.0, 1.0]]


def test_at_edge_turns_towards_the_nearest_edge():
    assert adversary_actions(Adversary.AT_EDGE, one_uav(3, 50, 90, [])).tolist() == [[1.0, 1.0]]  # west: turn left
    assert adversary_actions(Adversary.AT_EDGE, one_uav(3, 50, 180, [])).tolist() == [[0.0, 1.0]]
    assert adversary_actions(Adversary.AT_EDGE, one_uav(50, 97, 0, [])).tolist() == [[1.0, 1.0]]  # north
    assert adversary_actions(Adversary.AT_EDGE, one_uav(50, 4, 0, [])).tolist() == [[-1.0, 1.0]]  # south
    assert adversary_actions(Adversary.AT_EDGE, one_uav(98, 40, 93, [])).tolist() == [[-1.0, 1.0]]  # east


def test_random_is_uniform_new_each_decision_and_the_same_for_the_same_key():
    keys = np.arange(4000, dtype=np.uint64) * np.uint64(7919)
    draws = []
    for d in range(3):
        s = dataclasses.replace(
            one_uav(50, 50, 0, []),
            x_m=np.zeros(len(keys)),
            y_m=np.zeros(len(keys)),
            phi_rad=np.zeros(len(keys)),
            decision=np.full(len(keys), d),
            key=keys,
        )
        draws.append(adversary_actions(Adversary.RANDOM, s))
        assert np.array_equal(draws[-1], adversary_actions(Adversary.RANDOM, s))  # no state: the same again
    a = np.stack(draws)  # (3 decisions, 4000 UAVs, 2)
    assert a.min() >= -1.0 and a.max() < 1.0
    # Uniform on [-1, 1): mean 0 (s.e. 0.009), variance 1/3, each tenth of the range a tenth of the draws.
    assert abs(a.mean()) < 0.03 and a.var() == pytest.approx(1 / 3, abs=0.01)
    counts = np.histogram(a, bins=10, range=(-1, 1))[0]
    assert counts.min() > 0.09 * a.size and counts.max() < 0.11 * a.size
    # Independent across decisions, UAVs and the two components.
    assert abs(np.corrcoef(a[0, :, 0], a[1, :, 0])[0, 1]) < 0.05
    assert abs(np.corrcoef(a[0, :, 0], a[0, :, 1])[0, 1]) < 0.05
    assert abs(np.corrcoef(a[0, :-1, 0], a[0, 1:, 0])[0, 1]) < 0.05


def world_of(scenario: Scenario, layouts: list[Layout]) -> World:
    world = World(scenario, len(layouts))
    world.reset(np.arange(len(layouts)), layouts)
    return world


def test_a_mission_draws_the_same_random_actions_alone_and_from_the_file_fly_writes(tmp_path: Path):
    scenario = load(SCENARIOS / "random.yaml")
    layouts = [mission_layout(scenario, SEED, k) for k in range(4)]
    batch = layout_keys(snapshot(world_of(scenario, layouts)))
    assert len(set(batch.reshape(-1).tolist())) == batch.size  # every UAV of every layout its own stream
    # fly writes mission k's layout into a scenario file that the companions read.
    path = tmp_path / "mission.yaml"
    dump(dataclasses.replace(scenario, layout=layouts[2], random=None), path)
    fixed = load(path)
    assert fixed.layout is not None
    assert np.array_equal(layout_keys(snapshot(world_of(fixed, [fixed.layout])))[0], batch[2])


def test_the_companion_pilot_decides_as_the_batched_pilot():
    scenario = load(SCENARIOS / "random.yaml")
    layout = mission_layout(scenario, SEED, 0)
    for adversary in Adversary:
        batched = world_of(scenario, [layout])
        start = initial_state(scenario, layout)  # the companion's state, fed the estimate by with_vehicle
        batch_pilot = AdversaryPilot(adversary)
        pilots = [HeldPilot(AdversaryPilot(adversary)) for _ in ROLES]
        rng = np.random.default_rng(5)
        held = np.zeros((1, 3, 2))
        for step in range(35):
            if step % DECISION_STEPS == 0:
                held = np.stack([batch_pilot.actions(snapshot(batched), j) for j in range(3)], axis=1)
            for j, pilot in enumerate(pilots):
                mirror = start.with_vehicle(
                    j,
                    batched.x_m[0, j],
                    batched.y_m[0, j],
                    batched.v_m_s[0, j],
                    batched.phi_rad[0, j],
                    False,
                    False,
                    step,
                )
                action = pilot.action(lambda: mirror, j, step)
                assert pilot.decided == (step % DECISION_STEPS == 0), (adversary, step)
                # The mirror wraps the heading its own way: the same to the last bits or so.
                np.testing.assert_allclose(action, held[0, j], atol=1e-12, err_msg=f"{adversary} step {step} UAV {j}")
            batched.step(np.nan_to_num(held) + rng.uniform(-0.2, 0.2, held.shape))  # somewhere else each step


def test_the_companion_flies_the_pilot_it_is_given():
    strike = load(SCENARIOS / "strike.yaml")
    for name in PILOT_NAMES:
        companion = build_companion(CompanionConfig("udpout:127.0.0.1:9", Role.STRIKE, strike, pilot=name))
        assert companion.pilot_step.pilot.name == name
        assert isinstance(companion.pilot_step.pilot.pilot, AdversaryPilot) == (name in {a.value for a in Adversary})


# ---------------------------------------------------------------------------------------------- batched world


@pytest.fixture(scope="module")
def layout_sets() -> dict[str, tuple[Scenario, list[Layout]]]:
    """random.yaml's first missions of SEED, and corner.yaml's (starts 1-4 km from the corner), 150 s each."""
    sets = {}
    for name, count in (("random", RANDOM_LAYOUTS), ("corner", CORNER_LAYOUTS)):
        scenario = dataclasses.replace(load(SCENARIOS / f"{name}.yaml"), episode_steps=STEPS)
        sets[name] = (scenario, [mission_layout(scenario, SEED, k) for k in range(count)])
    return sets


def hazards(results: MissionResults) -> list[str]:
    """Each UAV-mission that entered a radar or left the area: mission index (of seed SEED), role, what."""
    rows = []
    for k, j in zip(*np.nonzero((results.cost > 0) | results.out_of_area)):
        what = f"{results.cost[k, j]:.0f} steps in a radar" if results.cost[k, j] else "left the area"
        rows.append(f"mission {k} {ROLES[j].value}: {what}")
    return rows


DANGEROUS_ON = {Adversary.TURN_LEFT: "corner", Adversary.TURN_RIGHT: "corner"}
"""Where each adversary meets a radar or an edge within 150 s without the monitor (random.yaml for the others):
from random.yaml's starts a full turn's 6.9 km circle reaches neither."""

# One test process runs this file: its module fixture is built once.
pytestmark = pytest.mark.xdist_group("test_adversaries")


@pytest.mark.parametrize("adversary", list(Adversary), ids=str)
def test_without_the_monitor_every_adversary_enters_radars_or_leaves(adversary, layout_sets):
    scenario, layouts = layout_sets[DANGEROUS_ON.get(adversary, "random")]
    alone = fly_missions(scenario, [AdversaryPilot(adversary)] * 3, 0, SEED, layouts=layouts)
    unsafe = ((alone.cost > 0) | alone.out_of_area).any(axis=1)
    assert unsafe.mean() >= 0.8, f"{adversary}: {unsafe.mean():.0%} of the missions unsafe"


MONITOR_CI_TIER = {Adversary.AT_RADAR, Adversary.TURN_RIGHT, Adversary.RANDOM}
"""The adversaries CI flies against the monitor (the ones that aim at a radar, hug a turn, and draw anything); the
others fly in the slow tier (``pytest -m slow``)."""


@pytest.mark.parametrize(
    "adversary",
    [pytest.param(a, id=str(a), marks=() if a in MONITOR_CI_TIER else pytest.mark.slow) for a in Adversary],
)
def test_with_the_monitor_no_adversary_enters_a_radar_or_leaves(adversary, layout_sets):
    pilots = [AdversaryPilot(adversary)] * 3
    for name, (scenario, layouts) in layout_sets.items():
        shielded = fly_missions(scenario, pilots, 0, SEED, layouts=layouts, shield=ShieldConfig())
        assert shielded.monitor is not None
        assert not hazards(shielded), f"{adversary} on {name} (seed {SEED}): {hazards(shielded)}"
        assert shielded.monitor.unprotected_steps.sum() == 0  # every start admitted: the guarantee holds
        assert (shielded.time_s == STEPS * scenario.dt_s).all()  # flown to the cap, none ended early
        if DANGEROUS_ON.get(adversary, "random") == name:
            assert shielded.monitor.interventions.any(axis=1).mean() >= 0.8  # the monitor had work to do
        if adversary is Adversary.NAN:  # a NaN action never flies: the backup flies all along
            assert np.array_equal(shielded.monitor.backup_steps, shielded.monitor.flown_steps)
