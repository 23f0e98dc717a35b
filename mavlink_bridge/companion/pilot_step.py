"""One control tick's pilot: the filter's estimate turned into the mission as the pilot sees it, the pilot asked for an
action (held between its decisions, :class:`~mavlink_bridge.companion.held_pilot.HeldPilot`), what is amiss turned
into what flies, and, with the runtime-assurance monitor, every tick handed to it (:mod:`.shield`): its choice flies.

Without the monitor what is amiss (no position fix yet, a telemetry gap longer than ``hold_after_s``, a non-finite
action) flies as the hold setpoint, and a non-finite action resets the pilot. With it, every tick goes through the
monitor: before the first fix its backup flies from the scenario's start flown through what was sent; a telemetry gap
or a non-finite action is a proposal that never passes (NaN), so the remembered backup flies, as in the batched world.
The monitor decides at the pilot's decision ticks (:class:`~mavlink_bridge.companion.held_pilot.DecisionClock`) and
its choice is held in between.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mavlink_bridge.companion.config import CompanionConfig
from mavlink_bridge.companion.held_pilot import DecisionClock, HeldPilot, make_pilot
from mavlink_bridge.companion.shield import CompanionShield, Estimate
from mavlink_bridge.companion.status import CompanionCounters, MissionFlags
from mavlink_bridge.estimation.state_filter import VehicleStateFilter
from mavlink_bridge.link.frames import HOLD, Setpoint, action_to_setpoint, setpoint_to_action
from tssac_core.sim.airframe_response import load_response
from tssac_core.sim.pilot_view import PilotView
from tssac_core.sim.scenario import VehicleSpec
from tssac_core.sim.world_state import WorldState, initial_state
from tssac_core.wire.mission_events import EventName

_log = logging.getLogger("mavlink_bridge.companion")

NO_FIX = "no position fix yet"
NONFINITE = "non-finite action"


@dataclass(frozen=True)
class PilotDecision:
    """What flies at one tick, and why."""

    setpoint: Setpoint
    why: str | None
    """What is amiss (None: nothing)."""
    gap_seen: bool | None
    """What the tick says of a telemetry gap: True, the tick is in one; False, the pilot's proposal flies again (with
    the monitor, a non-finite one too); None, it says nothing (no fix yet, or a non-finite action without the
    monitor)."""
    handover: str | None = None
    """The monitor's hand-over at this tick, to be said to the vehicle (None: none)."""


class PilotStep:
    """The pilot, the monitor and their decision ticks for one vehicle: :meth:`decide` is a control tick's whole
    pilot side (see the module docstring)."""

    def __init__(
        self,
        pilot: HeldPilot,
        shield: CompanionShield | None,
        layout_state: WorldState,
        spec: VehicleSpec,
        role_index: int,
        dt_ms: int,
        hold_after_s: float,
        counters: CompanionCounters,
    ) -> None:
        self.pilot = pilot
        self.shield = shield
        """The runtime-assurance monitor; None: the pilot alone."""
        self.layout_state = layout_state
        """The mission's start as the pilot is shown it (:mod:`tssac_core.sim.pilot_view`; the monitor has the truth);
        each tick the filter's estimate replaces this vehicle's state."""
        self.spec = spec
        self.role_index = role_index
        self.dt_ms = dt_ms
        self.hold_after_s = hold_after_s
        self.counters = counters
        self.decisions = DecisionClock(pilot.repeat)
        """The monitor's decision ticks."""

    @classmethod
    def of(cls, config: CompanionConfig, counters: CompanionCounters) -> PilotStep:
        """The pilot a configuration names, its monitor if it asks for one, and the pilot warmed up (the guidance
        plans its route) on the mission's start."""
        s = config.scenario
        assert s.layout is not None
        pilot = make_pilot(config)
        layout_state = initial_state(s, s.layout)
        shield = (
            None
            if config.shield is None
            else CompanionShield(
                layout_state,
                config.role,
                s,
                config.shield,
                config.lockstep,
                None if config.airframe_response is None else load_response(config.airframe_response),
            )
        )
        shown = PilotView.asked_by(config.shield).of(layout_state)  # the monitor's room asked of the pilot
        pilot.action(lambda: shown, config.role.index, 0)  # warm up: the guidance plans its route
        pilot.reset()
        spec = s.vehicle(config.role)
        dt_ms = int(round(s.dt_s * 1000.0))
        return cls(pilot, shield, shown, spec, config.role.index, dt_ms, config.hold_after_s, counters)

    def reset(self) -> None:
        """Forget the flight (at the start and after a vehicle restart): the pilot's held action and the decision
        ticks. The monitor is reset on its own (:meth:`CompanionShield.reset`), at a restart."""
        self.decisions = DecisionClock(self.pilot.repeat)
        self.pilot.reset()

    def gap_s(self, f: VehicleStateFilter, t_ms: int) -> float:
        """Vehicle seconds from the last position fix to tick ``t_ms``, if no fix came in between."""
        return t_ms / 1000.0 - f.last_measurement_t_s

    def decide(self, t_ms: int, f: VehicleStateFilter, flags: MissionFlags) -> PilotDecision:
        """What flies at vehicle time ``t_ms`` from the filter ``f`` (predicted to the tick here) and the mission
        ``flags`` the datalink told (see the module docstring)."""
        step = int(t_ms // self.dt_ms)
        if not f.initialised:
            if self.shield is None:
                return PilotDecision(HOLD, NO_FIX, None)
            # Nothing to propose from, but the start is known: the monitor flies its backup from where the vehicle
            # is (the start flown through what was sent), as the start check admitted it to.
            return self._shielded(np.full(2, np.nan), step, f, NO_FIX, None, lambda: self._start_reckoned(step))
        f.predict_to(t_ms / 1000.0)
        gap_s = self.gap_s(f, t_ms)
        if gap_s > self.hold_after_s:
            gap = f"telemetry gap {gap_s:.1f} s"
            if self.shield is None:
                return PilotDecision(HOLD, gap, True)
            return self._shielded(np.full(2, np.nan), step, f, gap, True)
        action = self.pilot.action(lambda: self._estimated_state(step, f, flags), self.role_index, step)
        why: str | None = None
        if action.shape != (2,) or not (math.isfinite(action[0]) and math.isfinite(action[1])):
            self.counters.nonfinite_actions += 1
            why = NONFINITE
            if self.shield is None:
                self.pilot.reset()
                return PilotDecision(HOLD, why, None)
            action = np.full(2, np.nan)
        if self.shield is not None:
            return self._shielded(action, step, f, why, False)
        return PilotDecision(action_to_setpoint((float(action[0]), float(action[1])), self.spec), None, False)

    def _estimated_state(self, step: int, f: VehicleStateFilter, flags: MissionFlags) -> WorldState:
        """The mission as the pilot sees it at tick ``step``: the layout, this vehicle at the filter's estimate, the
        flags the datalink told."""
        x_m, y_m = f.pos_m
        return self.layout_state.with_vehicle(
            self.role_index,
            x_m,
            y_m,
            f.speed_m_s,
            f.heading_rad,
            bool(flags.get(EventName.RADAR_ON)),
            bool(flags.get(EventName.IDENT)),
            step,
        )

    def _start_reckoned(self, step: int) -> Estimate:
        """Before the first fix: the scenario's start of this vehicle flown to tick ``step`` (its sigmas zero)."""
        assert self.shield is not None
        s, j = self.layout_state, self.role_index
        start = (float(s.x_m[0, j]), float(s.y_m[0, j]), float(s.v_m_s[0, j]), float(s.phi_rad[0, j]))
        return self.shield.dead_reckoned(start, step)

    def _shielded(
        self,
        proposed: np.ndarray,
        step: int,
        f: VehicleStateFilter,
        why: str | None,
        gap_seen: bool | None,
        estimate: Callable[[], Estimate] | None = None,
    ) -> PilotDecision:
        """The monitor's choice at each decision tick (held between them), and its hand-over if there is one.

        Decision ticks are the pilot's grid, ticks 0, k, 2k, ... of the vehicle's clock (k = the pilot's
        ``repeat``; a tick skipped by a slow companion moves the decision to the next tick seen), whether or not
        the pilot was asked this tick."""
        assert self.shield is not None
        decision = self.decisions.due(step)
        action, text = self.shield.action(
            decision, self.pilot.repeat, proposed, estimate or (lambda: self._monitor_estimate(f)), step
        )
        setpoint = action_to_setpoint((float(action[0]), float(action[1])), self.spec)
        return PilotDecision(setpoint, why, gap_seen, text)

    def _monitor_estimate(self, f: VehicleStateFilter) -> Estimate:
        """What the monitor decides on: the filter's (x, y, v, phi), its sigmas of position (major axis), heading
        and speed, and its turn rate with its sigma (a filter without one: 0, as uncertain as the limit allows)."""
        x_m, y_m = f.pos_m
        rate, rate_sigma = f.turn_rate_rad_s, f.turn_rate_sigma_rad_s
        unknown = (0.0, math.radians(self.spec.turn_rate_max_deg_s))
        turn = unknown if rate is None or rate_sigma is None else (rate, rate_sigma)
        sigmas = (f.position_sigma_major_m, *f.speed_heading_sigma[::-1])
        return (x_m, y_m, f.speed_m_s, f.heading_rad), sigmas, turn

    def start_turn_rate(self, t_ms: int) -> tuple[float, float] | None:
        """What the filter may start from at the first fix, at tick ``t_ms``: the monitor's known straight start
        (:meth:`~mavlink_bridge.companion.shield.CompanionShield.straight_start_turn_rate`), or None."""
        return None if self.shield is None else self.shield.straight_start_turn_rate(t_ms // self.dt_ms)

    def sent(self, setpoint: Setpoint, t_ms: int, before_fix: bool) -> None:
        """``setpoint`` was sent (or a grant answered with it) at tick ``t_ms``: the monitor counts it on the link
        (``before_fix``: the vehicle's position is not yet known)."""
        if self.shield is not None:
            self.shield.sent(setpoint_to_action(setpoint, self.spec), t_ms // self.dt_ms, before_fix)

    def held_setpoint(self) -> Setpoint:
        """What is sent again while the link is silent: the command the monitor chose for this tick (a new one could
        start nowhere the monitor checked); without the monitor, the hold."""
        return HOLD if self.shield is None else action_to_setpoint(tuple(self.shield.held), self.spec)

    def next_change_step(self, step: int) -> int:
        """The first tick after ``step`` (decided already) at which what flies may change: the pilot's next decision,
        and with the monitor its next decision and a backup's turn after its lead."""
        next_step = self.pilot.next_decision_step(step)
        if self.shield is not None:
            next_step = min(next_step, max(step + 1, self.decisions.next_step))
            turn = self.shield.next_change_step  # a backup's turn after its lead, before the next decision
            if turn is not None:
                next_step = min(next_step, max(step + 1, turn))
        return next_step
