"""The runtime-assurance monitor in the training worlds (tssac_core.sim.role_task.MonitorInTraining): every UAV flies
through it, a step it overrules the learner costs the learner 1, the worlds it forgets are those that start anew, and
a resumed task flies on with the monitor's memory."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest

from tssac_core.assurance.ground_loiter import LoiterBound
from tssac_core.assurance.monitor import Memory, ShieldConfig
from tssac_core.common.cli import run
from tssac_core.sim.airframe_response import load_response
from tssac_core.sim.observation import observe
from tssac_core.sim.role_task import MonitorInTraining, RoleTask
from tssac_core.sim.scenario import Role, Scenario, load
from tssac_core.sim.varied_airframes import AirframeVariation
from tssac_core.sim.world_state import snapshot
from tssac_core.train.cli import main

ROOT = Path(__file__).resolve().parent.parent
F16_RESPONSE = ROOT / "sim_vehicles" / "dynamics" / "airframes" / "f16.response.yaml"


@pytest.fixture
def scenario(random_path: Path) -> Scenario:
    return load(random_path)


def steer_into_radar(obs: np.ndarray) -> np.ndarray:
    """A hostile learner: full speed, full turn towards the nearest radar's centre (the extended observation's
    bearing to it, relative to the heading)."""
    bearing = np.arctan2(obs[:, 13], obs[:, 12])
    return np.stack([np.clip(3.0 * bearing, -1.0, 1.0), np.ones(len(obs))], axis=1)


@functools.cache
def f16_in_wind() -> tuple[AirframeVariation, LoiterBound]:
    """Airframes from the F-16 response's spans in winds up to 10 m/s, and the loiter's bound for them (a few seconds
    to fit: once)."""
    response = load_response(F16_RESPONSE)
    variation = AirframeVariation.from_response(response, wind_max_m_s=10.0)
    return variation, variation.envelope_loiter_bound(response.loiter_law(), load(ROOT / "scenarios" / "random.yaml"))


def task_for(
    scenario: Scenario, monitored: bool, in_wind: bool, seed: int = 3, costs_overrule: bool = True
) -> RoleTask:
    variation, loiter = f16_in_wind() if in_wind else (None, None)
    monitor = MonitorInTraining(ShieldConfig(adjust=True), 10, loiter, costs_overrule) if monitored else None
    return RoleTask(scenario, Role.DECOY, n=4, teammates="none", seed=seed, airframes=variation, monitor=monitor)


def fly_into_radars(task: RoleTask, decisions: int) -> tuple[np.ndarray, np.ndarray]:
    """The learner's cost and its eq. 11 hazard cost, summed per world over ``decisions`` decisions of the first
    episodes (none of them ends that soon)."""
    obs = task.reset()
    cost = np.zeros(task.n)
    for _ in range(decisions):
        step = task.step(steer_into_radar(obs), repeat=10)
        assert not (step.terminated | step.truncated).any()
        obs, cost = step.obs, cost + step.cost
    return cost, task.world.cost_total[:, task.j].astype(np.float64)


@pytest.mark.parametrize("in_wind", [False, True], ids=["eq5", "f16-airframes-in-wind"])
def test_a_learner_steering_into_radars_pays_for_every_step_the_monitor_flies_and_never_enters(
    scenario: Scenario, in_wind: bool
) -> None:
    alone_cost, alone_hazard = fly_into_radars(task_for(scenario, False, in_wind), 200)
    assert (alone_hazard > 0).all()  # the negative control: unmonitored, every world's learner gets in
    np.testing.assert_array_equal(alone_cost, alone_hazard)
    task = task_for(scenario, True, in_wind)
    cost, hazard = fly_into_radars(task, 200)
    assert task.monitor is not None
    counts = task.monitor.counts
    assert (hazard == 0).all()
    overruled = counts.backup_steps[:, 0] + counts.adjusted_steps[:, 0]
    assert (overruled > 0).all()
    np.testing.assert_array_equal(cost, overruled)  # 1 per world step the monitor flew instead of the learner


def test_as_a_shield_the_monitor_flies_the_same_and_the_learner_pays_only_the_hazards_cost(scenario: Scenario) -> None:
    costed = task_for(scenario, True, False)
    costed_cost, _ = fly_into_radars(costed, 200)
    shielded = task_for(scenario, True, False, costs_overrule=False)
    cost, hazard = fly_into_radars(shielded, 200)
    assert costed.monitor is not None and shielded.monitor is not None
    np.testing.assert_array_equal(shielded.world.phi_rad, costed.world.phi_rad)  # the same monitor, the same flight
    assert (costed_cost > 0).all() and (hazard == 0).all()
    np.testing.assert_array_equal(cost, np.zeros(shielded.n))  # what was flown never entered a radar: no cost


def test_the_monitor_forgets_only_the_worlds_that_start_anew(scenario: Scenario) -> None:
    task = task_for(scenario, True, False)
    fly_into_radars(task, 200)
    monitor = task.monitor
    assert monitor is not None and monitor.overruled[:, 0].any()
    before = (monitor.memory.engaged.copy(), monitor.counts.flown_steps.copy(), monitor.overruled.copy())
    task.reset(np.array([1, 2]))
    fresh = Memory.initial(6)
    rows = np.arange(3, 9)
    np.testing.assert_array_equal(monitor.memory.engaged[rows], fresh.engaged)
    np.testing.assert_array_equal(monitor.memory.backup[rows], fresh.backup)
    assert not monitor.overruled[1:3].any() and (monitor.counts.flown_steps[1:3] == 0).all()
    kept = np.r_[0:3, 9:12]
    np.testing.assert_array_equal(monitor.memory.engaged[kept], before[0][kept])
    np.testing.assert_array_equal(monitor.counts.flown_steps[[0, 3]], before[1][[0, 3]])
    np.testing.assert_array_equal(monitor.overruled[[0, 3]], before[2][[0, 3]])


def test_a_resumed_task_flies_on_with_the_monitors_memory(scenario: Scenario) -> None:
    task = task_for(scenario, True, True)
    fly_into_radars(task, 80)
    saved = task.state()

    def fly_on(t: RoleTask) -> np.ndarray:
        obs = observe(snapshot(t.world), t.j, t.mode, t.obs_routes)
        costs = []
        for _ in range(30):
            step = t.step(steer_into_radar(obs), repeat=10)
            obs = step.obs
            costs.append(np.concatenate([step.cost, obs.reshape(-1)]))
        return np.array(costs)

    other = task_for(scenario, True, True, seed=99)
    other.restore(saved)
    np.testing.assert_array_equal(fly_on(other), fly_on(task))
    plain = task_for(scenario, False, True)
    with pytest.raises(ValueError, match="monitor"):
        task_for(scenario, True, True).restore(plain.state())


@pytest.mark.parametrize("value", ["maybe", "yes"])
def test_a_preset_with_a_bad_train_monitor_word_is_one_line(tmp_path: Path, capsys, value: str) -> None:
    preset = tmp_path / "p.yaml"
    preset.write_text(f"train_monitor: {value}\n")  # YAML 1.1 reads an unquoted yes as true: a word is refused too
    assert run(main, ["--preset", str(preset), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "train_monitor: expected one of off, on, shield" in err
    assert not (tmp_path / "run").exists()
