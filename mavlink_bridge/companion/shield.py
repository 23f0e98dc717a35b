"""The runtime-assurance monitor in a companion computer: :func:`tssac_core.assurance.monitor.decide` for one
vehicle, fed with the Kalman filter's estimate, its covariance and the commands still on the link.

At each decision (every ``action_repeat`` ticks of the vehicle's clock; every tick for the guidance controller)
the proposed action goes through :class:`tssac_core.sim.world_monitor.VehicleMonitor` with

* the filter's estimate (x, y, v, phi) at the tick;
* the margin (:func:`~tssac_core.assurance.monitor.companion_margin_m`): the base, and off lockstep v_max times
  the timing slack;
* the error bound (:func:`~tssac_core.assurance.monitor.companion_error`): ``sigma_k`` standard deviations of the
  filter's position (major axis), heading and speed, and over a lossy link or off lockstep one setpoint lost or
  late at a command change; the monitor takes it off each backup's clearance by that backup's lever arms;
* the commands sent in the last round trip (``pending``): the vehicle flies the setpoint stamped for tick t
  about 2 x ``link.latency_ms`` after t, off lockstep and in lockstep alike (there the link runs on simulated
  time). Before the first command reached the vehicle it flew the hold (straight on): the queue starts with it;
* with an airframe's response (``--airframe-response``), the paths predicted with its lag
  (:class:`~tssac_core.assurance.lagged_prediction.LaggedPrediction`) instead of eq. 5: from the filter's turn rate,
  with the turn commands the airframe has not yet followed (its delay, before the link's round trip); the turn
  rate's error, ``sigma_k`` standard deviations, turns the path by at most that times the longer time constant
  (the lag closes an error in the rate as it closes a gap to the command);
* in a scenario that promises wind, with a response whose ground loiter was fitted (``loiter_*``), the backups end in
  the ground loiter (:mod:`tssac_core.assurance.ground_loiter`): the monitor decides on the air's part of the
  filter's ground velocity (less the wind the vehicle reports in WIND, the scenario's until the first report), and
  where a flying backup's lead ends the loiter's centre is fixed from the estimate, whose position, ground velocity
  and the wind give every tick's heading rate from then on (a closed loop: the command changes every tick).

Every tick's command comes from here: a non-finite action and a telemetry gap are proposals that never pass (the
remembered backup flies, as in the batched world), and between decisions the monitor's last choice is held.
Each hand-over is said to the vehicle in a STATUSTEXT (``"<role>: shield on, backup <turn>"`` /
``"<role>: shield off, policy flies"``), which the SITL vehicle relays to its other clients and logs.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeAlias

import numpy as np

from mavlink_bridge.companion.vehicle_limits import monitor_fit
from tssac_core.assurance.ground_loiter import LoiterBound, loiter_action, loiter_centre
from tssac_core.assurance.held_course import LineLaw, line_turn_rate
from tssac_core.assurance.lagged_backups import AirframeLag, LagState, lagged_rollout
from tssac_core.assurance.lagged_prediction import LaggedPrediction
from tssac_core.assurance.monitor import (
    KINEMATIC,
    N_TURNS,
    Decision,
    EstimateError,
    Memory,
    Prediction,
    Scene,
    ShieldConfig,
    companion_error,
    companion_margin_m,
    largest_backup_error_m,
    step_actions,
)
from tssac_core.sim.airframe_response import AirframeResponse, airframe_lag
from tssac_core.sim.lagged_starts import STRAIGHT_START_TURN_SIGMA_RAD_S
from tssac_core.sim.scenario import Role, Scenario
from tssac_core.sim.world_monitor import VehicleMonitor
from tssac_core.sim.world_state import WorldState
from tssac_core.wire.vehicle_limits import Achievable

ENGAGED_TEXT = "shield on"
RELEASED_TEXT = "shield off"
_TURN_NAMES = ("left", "right", "left braking", "right braking")

Estimate: TypeAlias = tuple[tuple[float, float, float, float], tuple[float, float, float], tuple[float, float]]
"""The filter's (x, y, v, phi) at a tick, its standard deviations of position (major axis, m), heading (rad) and
speed (m/s), and its turn rate and that's standard deviation (rad/s)."""


@dataclass
class ShieldCounters:
    """The monitor's counts over a companion's flight (in its status JSON)."""

    decisions: int = 0
    interventions: int = 0
    """Times the backup took over."""
    releases: int = 0
    """Times control went back to the policy."""
    backup_steps: int = 0
    """Control steps flown under the backup."""
    adjusted_steps: int = 0
    """Control steps flown under the monitor's adjusted action (``ShieldConfig.adjust``)."""
    held_steps: int = 0
    """Control steps a backup's lead flew holding its line (:mod:`tssac_core.assurance.held_course`)."""
    unprotected_steps: int = 0
    """Control steps with no passing action and no clear backup."""
    resets: int = 0
    """Times the monitor started afresh (a vehicle restart)."""
    max_margin_m: float = 0.0
    """The most clearance a backup had to keep: the margin and the largest error bound over the backups."""
    nonfinite_proposals: int = 0
    """Decisions whose proposal was not finite (a non-finite action, or none in a telemetry gap): the backup flew."""


class CompanionShield:
    """One vehicle's monitor with its held action, its queue of sent commands and its counts."""

    def __init__(
        self,
        state: WorldState,
        role: Role,
        scenario: Scenario,
        cfg: ShieldConfig,
        lockstep: bool,
        response: AirframeResponse | None = None,
    ) -> None:
        promised = 0.0 if scenario.wind is None else scenario.wind.promised_max_m_s
        if response is not None and response.held_leads_s and promised == 0.0:  # calm air: the held leads as well
            cfg = cfg.with_leads(response.held_leads_s)
        self.cfg = cfg
        self.role = role
        self.response = response
        """The airframe's fitted response the monitor predicts with (None: eq. 5)."""
        self.monitor = VehicleMonitor(state, role.index, cfg)
        self.dt_s = scenario.dt_s
        self.latency_s = scenario.link.latency_ms / 1000.0
        self.off_lockstep = not lockstep
        self.lossy = not lockstep or scenario.link.setpoints_may_slip(scenario.dt_s)
        self.speed_max_m_s = scenario.vehicle(role).speed_max_m_s
        self.counters = ShieldCounters()
        self.engaged = False
        self._adjusted = False
        self._unprotected = False
        self._held = np.zeros(2)
        self._turn = np.zeros(2)
        self._turn_step: int | None = None
        """The tick at which a flying backup's turn follows its straight lead, before the next decision (None: none)."""
        self._sent: deque[tuple[float, float]] = deque(maxlen=2000)
        self._before_fix: list[tuple[int, tuple[float, float]]] = []
        """(tick, command) of every command sent before the first position fix: what the vehicle flies from its start,
        for :meth:`dead_reckoned`."""
        self.loiter: LoiterBound | None = None if response is None or promised == 0.0 else response.loiter_bound()
        """The backups end in the ground loiter bounded by this (None: calm air's constant turn)."""
        wind = (0.0, 0.0) if scenario.wind is None else scenario.wind.velocity_m_s()
        self.wind_m_s = wind
        """The steady wind (east, north), m/s: the scenario's until the vehicle reports one (:meth:`set_wind`)."""
        self._circle: tuple[float, float, float, float] | None = None
        """The loiter flying now: its centre (x, y), radius and direction (+1 counter-clockwise); None: none."""
        self._loiter_step: int | None = None
        """The tick at which the flying backup's loiter starts, after its turn-in (None: none scheduled)."""
        self.line_law = LineLaw()
        """How a held lead holds its line (:mod:`tssac_core.assurance.held_course`)."""
        self._line: tuple[float, float, float] | None = None
        """The line a flying backup's lead holds now: a point on it (x, y) and its course; None: none."""
        self._hold_step: int | None = None
        """The tick at which the flying backup's lead begins to hold its course (None: none scheduled)."""
        self._tick = 0
        """The last tick :meth:`action` was asked for."""
        self.achievable: Achievable | None = None
        """What the vehicle said it achieves (:meth:`use_achievable`; None: it did not say, or was not asked)."""

    def use_achievable(self, achievable: Achievable | None) -> str | None:
        """Hold the monitor to what the vehicle says it achieves (None: it does not say; the scenario's limits stand):
        why it cannot fly the backups (one line), or None (:mod:`mavlink_bridge.companion.vehicle_limits`)."""
        lim = self.monitor.limits
        fit = monitor_fit(achievable, float(lim.turn_rate_max_rad_s[0]), float(lim.accel_max_m_s2[0]))
        self.achievable = achievable
        self.monitor.cfg = dataclasses.replace(
            self.cfg, braking_backups=self.cfg.braking_backups and fit.braking_backups
        )
        return fit.refusal

    def reset(self) -> None:
        """Forget the backup and the queue (a vehicle restart: a new flight)."""
        self.monitor.reset()
        self.engaged = False
        self._adjusted = False
        self._unprotected = False
        self._turn_step = None
        self._circle = None
        self._loiter_step = None
        self._line = None
        self._hold_step = None
        self._sent.clear()
        self._before_fix.clear()
        self.counters.resets += 1

    def pending_ticks(self) -> int:
        """Setpoints still on their way to the vehicle or not yet flown: a round trip of the link in ticks."""
        if self.latency_s <= 0:
            return 0
        return round(2.0 * self.latency_s / self.dt_s)

    @property
    def held(self) -> np.ndarray:
        """The command the monitor chose last (what the vehicle flies until the next tick's)."""
        return self._held.copy()

    def _pending(self) -> np.ndarray | None:
        """The commands of the last round trip, oldest first; hold commands before the first one sent."""
        n = self.pending_ticks()
        if n == 0:
            return None
        sent = list(self._sent)[-n:]
        return np.array([np.zeros(2)] * (n - len(sent)) + sent)

    @property
    def next_change_step(self) -> int | None:
        """The tick before the next decision at which the command changes (a backup's turn after its lead; while a
        loiter flies, the next tick), if any."""
        if self._circle is not None or self._line is not None:
            return self._tick + 1
        if self._loiter_step is not None:
            return self._loiter_step
        scheduled = [t for t in (self._hold_step, self._turn_step) if t is not None]
        return min(scheduled, default=None)

    def set_wind(self, east_m_s: float, north_m_s: float) -> None:
        """The wind the vehicle reports (WIND), as the air's velocity east and north (m/s); a report that is not finite
        is ignored (the last good one, or the scenario's, stays)."""
        if math.isfinite(east_m_s) and math.isfinite(north_m_s):
            self.wind_m_s = (east_m_s, north_m_s)

    def action(
        self,
        decision: bool,
        steps: int,
        proposed: np.ndarray,
        estimate: Callable[[], Estimate],
        step: int,
    ) -> tuple[np.ndarray, str | None]:
        """The action to send at tick ``step`` and a STATUSTEXT to say (a hand-over), or None.

        ``decision``: a decision tick (the choice holds for ``steps`` ticks, but for a backup whose straight lead ends
        in between: its turn from that tick on); otherwise the monitor's last choice is held. ``proposed``: the
        pilot's action, non-finite when there is none (it never passes). ``estimate()``: the filter's state and
        standard deviations (:data:`Estimate`), asked at decisions only."""
        text = None
        self._tick = step
        if not decision and self._turn_step is not None and step >= self._turn_step:
            self._held, self._turn_step = self._turn.copy(), None
            self._line, self._hold_step = None, None  # the lead ends: its turn flies
            if self.loiter is not None and self.engaged:
                self._loiter_step = step + self.loiter.turn_in_steps(self.dt_s)
        if decision:
            state, sigmas, (turn_rate, turn_sigma) = estimate()
            if self.loiter is not None:
                state, sigmas, turn_rate = self._in_the_air(state, sigmas, turn_rate)
            margin = companion_margin_m(self.cfg, self.speed_max_m_s, self.off_lockstep)
            lim = self.monitor.limits
            error = companion_error(self.cfg, lim, self.dt_s, *sigmas, lossy=self.lossy)
            prediction: Prediction = KINEMATIC
            if self.response is not None:
                airframe = self._airframe(state[2])
                wind = None
                if self.loiter is not None:
                    east, north = (np.array([c]) for c in self.wind_m_s)
                    wind = self.loiter.wind(east, north, np.array([state[2]]))
                prediction = LaggedPrediction(airframe, self._lag_state(airframe, turn_rate), wind)
                turned = self.cfg.sigma_k * turn_sigma * airframe.longest_tau_s()
                error = error + EstimateError(np.zeros(1), turned, np.zeros(1))
            if not np.all(np.isfinite(proposed)):
                self.counters.nonfinite_proposals += 1
            before = self.monitor.memory
            d = self.monitor.decide(
                *state,
                proposed=proposed,
                steps=steps,
                margin_m=margin,
                pending=self._pending(),
                error=error,
                prediction=prediction,
            )
            self._held = d.action[0].copy()
            self._turn = d.turn[0].copy()
            straight = int(d.straight_steps[0])
            self._turn_step = step + straight if 0 < straight < steps else None
            self.counters.decisions += 1
            scene = Scene(self.monitor.hazards, lim, self.dt_s, np.array([margin]), self.cfg)
            need = margin + largest_backup_error_m(error, steps, scene, prediction)
            self.counters.max_margin_m = max(self.counters.max_margin_m, need)
            if d.engaged_now[0]:
                self.counters.interventions += 1
                turn = _TURN_NAMES[int(d.memory.backup[0]) % N_TURNS]
                text = f"{self.role.value}: {ENGAGED_TEXT}, backup {turn}"
            elif d.released_now[0]:
                self.counters.releases += 1
                text = f"{self.role.value}: {RELEASED_TEXT}, policy flies"
            self.engaged = bool(d.engaged[0])
            self._adjusted = bool(d.adjusted[0])
            self._unprotected = bool(d.unprotected[0])
            if not self.engaged:
                self._circle, self._loiter_step = None, None
            elif self.loiter is not None and straight == 0 and self._circle is None and self._loiter_step is None:
                self._loiter_step = step + self.loiter.turn_in_steps(self.dt_s)
            self._schedule_hold(d, before, step, straight, prediction)
        self._closed_loop(step, estimate)
        self._count_tick()
        return self._held, text

    def _count_tick(self) -> None:
        """One control step under the adjusted action, the backup, or without a clear backup."""
        self.counters.adjusted_steps += self._adjusted
        self.counters.held_steps += self._line is not None
        self.counters.backup_steps += self.engaged
        self.counters.unprotected_steps += self.engaged and self._unprotected

    def _in_the_air(
        self, state: tuple[float, float, float, float], sigmas: tuple[float, float, float], turn_rate: float
    ) -> tuple[tuple[float, float, float, float], tuple[float, float, float], float]:
        """The filter's ground state as the monitor's model flies it in wind: the air's velocity (the ground velocity
        less the wind) as speed and heading, the course rate as the heading rate (chi' = kappa |g|, psi' = chi' |g|^2
        / (V (V + w . h))), and the heading's sigma widened by |g| / V (the ground velocity turned by d turns the air's
        by at most d |g| / V)."""
        x, y, ground, course = state
        we, wn = self.wind_m_s
        gx, gy = ground * np.cos(course), ground * np.sin(course)
        ax, ay = gx - we, gy - wn
        air = float(np.hypot(ax, ay))
        along = (ax * gx + ay * gy) / air
        rate = turn_rate * ground**2 / (air * along) if along > 0 else turn_rate
        position, heading, speed = sigmas
        return (x, y, air, float(np.arctan2(ay, ax))), (position, heading * ground / air, speed), float(rate)

    def _closed_loop(self, step: int, estimate: Callable[[], Estimate]) -> None:
        """The closed-loop parts of a flying backup: the held lead's line and the loiter's circle, each fixed from the
        estimate when its tick comes, then flown every tick."""
        if self._circle is None and self._loiter_step is not None and step >= self._loiter_step:
            self._begin_loiter(estimate())
        if self._line is None and self._hold_step is not None and step >= self._hold_step:
            self._begin_hold(estimate())
        if self._line is not None:
            self._held = self._hold_action(estimate())
        if self._circle is not None:
            self._held = self._loiter_action(estimate())

    def _schedule_hold(self, d: Decision, before: Memory, step: int, straight: int, prediction: Prediction) -> None:
        """After a decision: a backup that started now with a held lead holds its course from the end of the lead's
        open part (its first command is sent now); a backup no longer flying, or whose lead has ended, holds nothing."""
        started = bool(d.engaged[0]) and not (bool(before.engaged[0]) and bool(before.protected[0]))
        if not self.engaged or straight == 0 or started:
            self._line, self._hold_step = None, None
        held_from = prediction.held_from_steps(self.dt_s)
        if started and held_from is not None and math.isfinite(float(d.memory.held_course[0])):
            self._hold_step = step + held_from

    def _begin_hold(self, estimate: Estimate) -> None:
        """Fix the held line: through the estimate's position, along the course the backup's check predicted."""
        (x, y, _, _), _, _ = estimate
        self._line = (x, y, float(self.monitor.memory.held_course[0]))
        self._hold_step = None

    def _hold_action(self, estimate: Estimate) -> np.ndarray:
        """This tick's command of the held lead: the line law's heading rate from the estimate, the speed held."""
        assert self._line is not None
        x, y, gx, gy, _ = self._ground_and_air(estimate)
        lx, ly, course = self._line
        limit = self.monitor.limits.turn_rate_max_rad_s
        line = (np.array([lx]), np.array([ly]), np.array([course]))
        rate = line_turn_rate(np.array([x]), np.array([y]), np.array([gx]), np.array([gy]), line, limit, self.line_law)
        return np.array([float(rate[0] / limit[0]), 0.0])

    def _ground_and_air(self, estimate: Estimate) -> tuple[float, float, float, float, float]:
        """The estimate's position, ground velocity (east, north) and airspeed (the ground velocity less the wind)."""
        (x, y, ground, course), _, _ = estimate
        we, wn = self.wind_m_s
        gx, gy = ground * np.cos(course), ground * np.sin(course)
        return x, y, float(gx), float(gy), float(np.hypot(gx - we, gy - wn))

    def _begin_loiter(self, estimate: Estimate) -> None:
        """Fix the loiter's circle where the flying backup's turn-in ends: at R from the estimate on the turn's side of
        its ground track."""
        assert self.loiter is not None
        x, y, gx, gy, air = self._ground_and_air(estimate)
        sign = 1.0 if int(self.monitor.memory.backup[0]) % N_TURNS == 0 else -1.0
        radius = self.loiter.radius_m(np.array([air]), self.monitor.limits.turn_rate_max_rad_s)
        cx, cy = loiter_centre(np.array([x]), np.array([y]), np.array([gx]), np.array([gy]), sign, radius)
        self._circle = (float(cx[0]), float(cy[0]), float(radius[0]), sign)

    def _loiter_action(self, estimate: Estimate) -> np.ndarray:
        """This tick's command of the flying loiter: the law's heading rate from the estimate and the wind, the speed
        held."""
        assert self.loiter is not None and self._circle is not None
        x, y, gx, gy, _ = self._ground_and_air(estimate)
        cx, cy, radius, sign = self._circle
        we, wn = self.wind_m_s
        circle = (np.array([cx]), np.array([cy]), np.array([radius]), sign)
        action = loiter_action(
            np.array([x]), np.array([y]), np.array([gx]), np.array([gy]), we, wn, circle,
            self.monitor.limits.turn_rate_max_rad_s, self.loiter.law,
        )  # fmt: skip
        return action[0]

    def _airframe(self, speed_m_s: float) -> AirframeLag:
        """The airframe's response at ``speed_m_s`` (held to the fitted span: the limits keep the speed inside it)."""
        assert self.response is not None
        speeds = self.response.speeds_m_s
        return airframe_lag(self.response, np.array([min(max(speed_m_s, speeds[0]), speeds[-1])]), self.dt_s)

    def _lag_state(self, airframe: AirframeLag, turn_rate_rad_s: float) -> LagState:
        """The lag's state where the link's round trip starts: the rate flown, and the turn commands sent before that
        round trip that the airframe's delay has not yet let it follow (oldest first; the hold before the first)."""
        delay, round_trip = int(airframe.delay_steps[0]), self.pending_ticks()
        turns = [command[0] for command in self._sent]
        before = turns[: len(turns) - round_trip] if round_trip else turns
        queue = ([0.0] * delay + before)[len(before) :] if delay else []
        w = self.monitor.limits.turn_rate_max_rad_s
        return LagState(np.array([turn_rate_rad_s]), np.array([queue], dtype=np.float64).reshape(1, delay) * w)

    def sent(self, action: tuple[float, float] | np.ndarray, step: int, before_fix: bool = False) -> None:
        """Record the command [omega, u] sent at tick ``step``, whatever sent it (the queue that ``pending`` is taken
        from; before the first fix, also what :meth:`dead_reckoned` flies)."""
        command = (float(action[0]), float(action[1]))
        self._sent.append(command)
        if before_fix:
            self._before_fix.append((step, command))

    def straight_start_turn_rate(self, step: int) -> tuple[float, float] | None:
        """What the filter may start from at the first fix, at tick ``step``, when the monitor predicts with an
        airframe's response: the start is straight, settled flight (the scenario's, as :meth:`dead_reckoned` takes
        it), so until a turn command reaches the vehicle its turn rate is 0 within the inner loop's steady error,
        (0, :data:`STRAIGHT_START_TURN_SIGMA_RAD_S`). None (the filter's own prior: as uncertain as the limit) once a
        turn may have begun, or for a monitor that predicts with eq. 5, which does not use the rate."""
        if self.response is None:
            return None
        delay = self.pending_ticks()
        if any(command[0] != 0.0 and tick + delay <= step for tick, command in self._before_fix):
            return None
        return 0.0, STRAIGHT_START_TURN_SIGMA_RAD_S

    def dead_reckoned(self, start: tuple[float, float, float, float], step: int) -> Estimate:
        """The vehicle's state at tick ``step`` before any position fix: its start (the scenario's: known exactly, in
        straight flight) flown through what it flew since tick 0: the hold until the first command reached it, then
        each command from its tick plus the link's round trip (the world's own integration, eq. 5-6, or with an
        airframe's response its lagged model). Its sigmas are zero; a setpoint lost or late is the error bound's
        hand-over term, as after a fix."""
        flown = np.zeros((max(step, 0), 2))
        delay = self.pending_ticks()
        for tick, command in self._before_fix:
            if tick + delay < len(flown):
                flown[tick + delay :] = command
        lim = self.monitor.limits
        x, y, v, phi = (np.array([value]) for value in start)
        turn_rate = 0.0
        if len(flown) and self.response is not None:
            airframe = self._airframe(start[2])
            path = lagged_rollout(
                x, y, v, phi, LagState.steady(np.zeros(1), int(airframe.delay_steps[0])),
                flown[None, :, 0] * lim.turn_rate_max_rad_s[:, None], flown[None, :, 1] * lim.accel_max_m_s2[:, None],
                airframe, lim, self.dt_s,
            )  # fmt: skip
            x, y, v, phi = path.xs[:, -1], path.ys[:, -1], path.speeds[:, -1], path.headings[:, -1]
            turn_rate = float(path.rates[0, -1])
        elif len(flown):
            x, y, v, phi = step_actions(x, y, v, phi, flown[None], lim, self.dt_s)
            turn_rate = float(flown[-1, 0] * lim.turn_rate_max_rad_s[0])
        state = (float(x[0]), float(y[0]), float(v[0]), float(phi[0]))
        if self.loiter is not None:  # in the wind: carried by it, and as the filter reports, over the ground
            state, turn_rate = self._over_the_ground(state, turn_rate, len(flown) * self.dt_s)
        return state, (0.0, 0.0, 0.0), (turn_rate, 0.0)

    def _over_the_ground(
        self, air: tuple[float, float, float, float], heading_rate: float, seconds: float
    ) -> tuple[tuple[float, float, float, float], float]:
        """A state flown ``seconds`` in the air mass (airspeed and heading) as the filter reports it: carried by the
        wind that long, its ground speed and course, its heading rate as the course rate (the inverse of
        :meth:`_in_the_air`)."""
        x, y, v, phi = air
        we, wn = self.wind_m_s
        gx, gy = v * np.cos(phi) + we, v * np.sin(phi) + wn
        ground = float(np.hypot(gx, gy))
        along = (v * np.cos(phi) * gx + v * np.sin(phi) * gy) / v
        course_rate = heading_rate * v * along / ground**2
        return (x + we * seconds, y + wn * seconds, ground, float(np.arctan2(gy, gx))), float(course_rate)
