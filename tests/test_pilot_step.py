"""A companion's pilot side of one control tick (mavlink_bridge.companion.pilot_step): what flies when the position is
not yet known, in a telemetry gap, on a non-finite action, and that with the runtime-assurance monitor every tick's
setpoint is the monitor's choice. No link: the filter is fed its fixes here."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mavlink_bridge.companion.config import CompanionConfig
from mavlink_bridge.companion.held_pilot import HeldPilot
from mavlink_bridge.companion.pilot_step import NO_FIX, NONFINITE, PilotStep
from mavlink_bridge.companion.shield import CompanionShield
from mavlink_bridge.companion.status import CompanionCounters, MissionFlags
from mavlink_bridge.estimation.state_filter import VehicleStateFilter
from mavlink_bridge.link.frames import HOLD, action_to_setpoint
from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.sim.adversaries import DECISION_STEPS
from tssac_core.sim.pilots import GuidancePilot
from tssac_core.sim.scenario import Role, load

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
ROLE = Role.STRIKE


def pilot_step(pilot: str = "guidance", shield: bool = False) -> PilotStep:
    scenario = load(SCENARIOS / "strike.yaml")
    config = CompanionConfig(
        "udpout:127.0.0.1:9", ROLE, scenario, pilot=pilot, shield=ShieldConfig() if shield else None
    )
    return PilotStep.of(config, CompanionCounters())


def fixed_filter(step: PilotStep, t_s: float) -> VehicleStateFilter:
    """A filter whose one fix, at ``t_s``, puts the vehicle at its start, flying north at its start speed."""
    s, j = step.layout_state, step.role_index
    f = VehicleStateFilter()
    assert f.update(t_s, (float(s.x_m[0, j]), float(s.y_m[0, j])), (0.0, float(s.v_m_s[0, j])))
    return f


def recorded_monitor(step: PilotStep) -> list[np.ndarray]:
    """The monitor's choices, recorded as it makes them."""
    shield = step.shield
    assert shield is not None
    choices: list[np.ndarray] = []
    decide = shield.action

    def recorded(*args, **kwargs):  # type: ignore[no-untyped-def]
        action, text = decide(*args, **kwargs)
        choices.append(np.array(action))
        return action, text

    shield.action = recorded  # type: ignore[method-assign]
    return choices


def test_without_the_monitor_what_is_amiss_flies_the_hold():
    step = pilot_step()
    flags = MissionFlags()
    no_fix = step.decide(0, VehicleStateFilter(), flags)
    assert (no_fix.setpoint, no_fix.why, no_fix.gap_seen) == (HOLD, NO_FIX, None)
    f = fixed_filter(step, 0.0)
    gap = step.decide(600, f, flags)  # 0.6 s after the fix: beyond hold_after_s (0.5 s)
    assert (gap.setpoint, gap.why, gap.gap_seen) == (HOLD, "telemetry gap 0.6 s", True)


def test_without_the_monitor_the_pilot_flies_on_the_estimate():
    step = pilot_step()
    f = fixed_filter(step, 1.0)
    decision = step.decide(1100, f, MissionFlags())
    assert decision.why is None and decision.gap_seen is False and decision.handover is None
    mirror = fixed_filter(step, 1.0)
    mirror.predict_to(1.1)
    x_m, y_m = mirror.pos_m
    state = step.layout_state.with_vehicle(
        step.role_index, x_m, y_m, mirror.speed_m_s, mirror.heading_rad, False, False, 11
    )
    expected = HeldPilot(GuidancePilot()).action(lambda: state, step.role_index, 11)
    assert decision.setpoint == action_to_setpoint((float(expected[0]), float(expected[1])), step.spec)


def test_without_the_monitor_a_non_finite_action_flies_the_hold_and_resets_the_pilot():
    step = pilot_step(pilot="nan")
    f = fixed_filter(step, 0.0)
    decision = step.decide(0, f, MissionFlags())
    assert (decision.setpoint, decision.why, decision.gap_seen) == (HOLD, NONFINITE, None)
    assert step.counters.nonfinite_actions == 1
    assert step.pilot.next_decision_step(0) == 1  # reset: it holds nothing, so it decides again at the next tick


@pytest.mark.parametrize("pilot", ["guidance", "nan"])
def test_with_the_monitor_every_tick_flies_the_monitors_choice(pilot: str):
    """No fix yet, the pilot's action (finite or not), a telemetry gap: each tick's setpoint is what the monitor
    chose, and a non-finite action or a gap is a proposal that never passes."""
    step = pilot_step(pilot=pilot, shield=True)
    choices = recorded_monitor(step)
    flags = MissionFlags()
    decisions = [step.decide(0, VehicleStateFilter(), flags)]
    f = fixed_filter(step, 0.1)
    decisions += [step.decide(t_ms, f, flags) for t_ms in (100, 200, 300)]
    decisions.append(step.decide(900, f, flags))  # 0.8 s after the last fix
    assert len(choices) == len(decisions)
    for decision, choice in zip(decisions, choices, strict=True):
        assert decision.setpoint == action_to_setpoint((float(choice[0]), float(choice[1])), step.spec)
    assert [d.why for d in decisions] == [NO_FIX] + [None if pilot == "guidance" else NONFINITE] * 3 + [
        "telemetry gap 0.8 s"
    ]
    assert [d.gap_seen for d in decisions] == [None, False, False, False, True]
    assert step.shield is not None
    # The NaN proposals the monitor decided on: at tick 0 (no fix) and, for the guidance (deciding every tick), at
    # tick 9 (the gap); the nan pilot's decision ticks are 0, 10, ...: between them the monitor's choice is held.
    assert step.shield.counters.nonfinite_proposals == (1 if pilot == "nan" else 2)


def test_what_flies_may_change_at_the_pilots_and_the_monitors_next_decision():
    alone = pilot_step(pilot="random")
    f = fixed_filter(alone, 0.0)
    alone.decide(0, f, MissionFlags())
    assert alone.next_change_step(0) == DECISION_STEPS  # the pilot holds its action until its next decision
    monitored = pilot_step(pilot="random", shield=True)
    monitored.decide(0, fixed_filter(monitored, 0.0), MissionFlags())
    assert monitored.next_change_step(0) <= DECISION_STEPS
    assert monitored.decisions.next_step == DECISION_STEPS


def test_in_a_link_silence_the_monitors_held_command_is_sent_again():
    assert pilot_step().held_setpoint() == HOLD
    step = pilot_step(shield=True)
    step.decide(0, fixed_filter(step, 0.0), MissionFlags())
    shield = step.shield
    assert isinstance(shield, CompanionShield)
    held = tuple(float(a) for a in shield.held)
    assert step.held_setpoint() == action_to_setpoint((held[0], held[1]), step.spec)


def test_the_pilot_step_is_built_from_the_configuration_and_its_pilot_warmed_up():
    step = pilot_step(pilot="straight", shield=True)
    assert step.pilot.name == "straight" and step.shield is not None
    assert step.dt_ms == 100 and step.hold_after_s == 0.5
    assert step.pilot.next_decision_step(0) == 1  # reset after the warm-up: it decides at the first tick
