"""The runtime-assurance monitor (:mod:`tssac_core.assurance.monitor`) driven over a batched :class:`World`.

Each vehicle is decided for at its pilot's decisions (every ``action_repeat`` world steps, every step for
the guidance controller), with the world's exact state: no estimate error, no latency. Between decisions
the action the monitor chose is held, as the pilots hold theirs, except where a flying backup's straight lead ends
between two decisions: its turn starts there (the leads are whole seconds whatever the decision interval).

With a loiter bound (``loiter``: the world's vehicles fly in wind, on airframes whose lag the monitor sees) a backup
ends in the ground loiter instead of a constant turn (:mod:`tssac_core.assurance.ground_loiter`): where its lead ends
the circle's centre is fixed from the vehicle's state, and from then on every step's heading rate is the loiter law's
from the state and the world's wind, until the policy flies again.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from tssac_core.assurance.ground_loiter import LoiterBound, loiter_action, loiter_centre
from tssac_core.assurance.held_course import LineLaw, line_turn_rate
from tssac_core.assurance.lagged_prediction import LaggedPrediction
from tssac_core.assurance.monitor import (
    KINEMATIC,
    N_TURNS,
    Decision,
    EstimateError,
    Hazards,
    Limits,
    Memory,
    Prediction,
    ShieldConfig,
    decide,
)
from tssac_core.sim.varied_airframes import VariedAirframes
from tssac_core.sim.world import N_ROLES, World
from tssac_core.sim.world_state import WorldState


@dataclass(frozen=True)
class DecisionError:
    """An error bound the batched monitor keeps as if it decided from an estimate, the same for every vehicle and
    decision (it still decides from the true state): what a companion's filter costs the team in clearance, measured
    apart from the filter itself (``benchmarks/bench_monitored_team.py --decision-error``). The figures are a
    companion's :func:`~tssac_core.assurance.monitor.companion_error` before a decision's interval: position (m),
    heading (rad, the turn rate's share included) and speed (m/s)."""

    position_m: float
    heading_rad: float
    speed_m_s: float

    def __post_init__(self) -> None:
        for name in ("position_m", "heading_rad", "speed_m_s"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"a decision error's {name} must be a finite number >= 0, got {value}")

    def rows(self, m: int) -> EstimateError:
        """The bound for ``m`` vehicles."""
        return EstimateError(np.full(m, self.position_m), np.full(m, self.heading_rad), np.full(m, self.speed_m_s))


@dataclass
class MonitorCounts:
    """Per world and vehicle, (N, 3)."""

    interventions: np.ndarray
    """Times the backup took over."""
    backup_steps: np.ndarray
    """World steps flown under the backup."""
    flown_steps: np.ndarray
    """World steps flown at all."""
    unprotected_steps: np.ndarray
    """Steps flown with no passing action and no clear backup (no guarantee)."""
    switches: np.ndarray
    """Hand-overs either way."""
    adjusted_steps: np.ndarray
    """World steps flown under the monitor's adjusted action (:attr:`ShieldConfig.adjust`)."""
    held_steps: np.ndarray
    """World steps a backup's lead flew holding its line (:mod:`tssac_core.assurance.held_course`)."""


class WorldMonitor:
    """Holds the monitor's memory for every vehicle of a World and filters the team's actions."""

    def __init__(
        self,
        world: World,
        repeats: list[int],
        cfg: ShieldConfig,
        airframes: VariedAirframes | None = None,
        loiter: LoiterBound | None = None,
        decision_error: DecisionError | None = None,
    ) -> None:
        if len(repeats) != N_ROLES:
            raise ValueError(f"one decision interval per role, got {repeats}")
        if loiter is not None and airframes is None:
            raise ValueError("the loiter's bound is measured for airframes: give the airframes it holds for")
        if airframes is not None and loiter is None and airframes.held_leads_s:
            cfg = cfg.with_leads(airframes.held_leads_s)  # calm air: the airframes' held leads as well
        self.cfg = cfg
        self.airframes = airframes
        """The world's vehicles fly these airframes (None: eq. 5-6): the monitor predicts with their lag."""
        self.loiter = loiter
        """The backups end in the ground loiter, bounded by this (None: a constant turn, calm air's backup)."""
        self.decision_error = decision_error
        """Kept off every decision's clearance as a companion's estimate error would be (None: the true state's 0)."""
        self.repeats = np.asarray(repeats, dtype=np.int64)
        n = world.n
        c = world.c
        self.limits = Limits(
            speed_min_m_s=np.tile(c.speed_min_m_s, n),
            speed_max_m_s=np.tile(c.speed_max_m_s, n),
            turn_rate_max_rad_s=np.tile(c.turn_rate_max_rad_s, n),
            accel_max_m_s2=np.tile(c.accel_max_m_s2, n),
        )
        self.memory = Memory.initial(n * N_ROLES)
        self._flying = np.zeros((n, N_ROLES, 2))
        self._turn = np.zeros((n, N_ROLES, 2))
        self._turn_at = np.full((n, N_ROLES), -1, dtype=np.int64)
        """The world step at which a flying backup's turn follows its lead (-1: none before the next decision)."""
        self._layout_version = -1
        self._hazards: Hazards | None = None
        zeros = np.zeros((n, N_ROLES), dtype=np.int64)
        self.counts = MonitorCounts(*(zeros.copy() for _ in dataclasses.fields(MonitorCounts)))
        self._engaged = np.zeros((n, N_ROLES), dtype=bool)
        self._adjusted = np.zeros((n, N_ROLES), dtype=bool)
        self._unprotected = np.zeros((n, N_ROLES), dtype=bool)
        self._loiter_sign = np.zeros((n, N_ROLES))
        """+1 / -1: the vehicle flies its backup's loiter, counter-clockwise / clockwise; 0: it does not."""
        self._loiter_centre = np.zeros((n, N_ROLES, 2))
        self._loiter_radius = np.ones((n, N_ROLES))
        self._loiter_at = np.full((n, N_ROLES), -1, dtype=np.int64)
        """The world step at which a flying backup's loiter starts, after its turn-in (-1: none scheduled)."""
        self.line_law = LineLaw()
        """How a held lead holds its line (:mod:`tssac_core.assurance.held_course`)."""
        self._hold_at = np.full((n, N_ROLES), -1, dtype=np.int64)
        """The world step at which a flying backup's lead begins to hold its course (-1: none scheduled)."""
        self._line = np.zeros((n, N_ROLES, 3))
        """The held line: a point on it (x, y) and its course, fixed where the hold begins."""
        self._holding = np.zeros((n, N_ROLES), dtype=bool)

    @property
    def engaged(self) -> np.ndarray:
        """(N, 3): the backup flies."""
        return self._engaged

    @property
    def overruled(self) -> np.ndarray:
        """(N, 3): the monitor flies something other than the pilot's proposal (its backup, or with
        :attr:`ShieldConfig.adjust` the passing action nearest the proposal)."""
        return self._engaged | self._adjusted

    def reset(self, worlds: np.ndarray) -> None:
        """Forget everything about the vehicles of ``worlds`` (indices): their worlds start new missions."""
        worlds = np.asarray(worlds, dtype=np.int64)
        flat = (worlds[:, None] * N_ROLES + np.arange(N_ROLES)[None, :]).reshape(-1)
        self.memory = self.memory.merged(flat, Memory.initial(len(flat)))
        for held in (self._flying, self._turn):
            held[worlds] = 0.0
        self._turn_at[worlds] = -1
        for flag in (self._engaged, self._adjusted, self._unprotected):
            flag[worlds] = False
        self._loiter_sign[worlds] = 0.0
        self._loiter_at[worlds] = -1
        self._hold_at[worlds] = -1
        self._holding[worlds] = False
        for field in dataclasses.fields(MonitorCounts):
            getattr(self.counts, field.name)[worlds] = 0

    def hazards(self, world: World) -> Hazards:
        """The layout per vehicle (each world's radars repeated for its three UAVs), rebuilt on a new layout."""
        if self._hazards is None or self._layout_version != world.layout_version:
            centres = np.repeat(world.radar_m, N_ROLES, axis=0)
            radii = np.repeat(world.radar_r_m, N_ROLES, axis=0)
            self._hazards = Hazards(centres, radii, world.c.area_m)
            self._layout_version = world.layout_version
        return self._hazards

    def actions(self, world: World, proposed: np.ndarray) -> np.ndarray:
        """The actions (N, 3, 2) to step the world with, given the pilots' ``proposed`` ones."""
        moving = world.active & world.running[:, None]
        turning = moving & (self._turn_at == world.steps[:, None])
        self._flying[turning] = self._turn[turning]
        self._holding[turning] = False  # the lead ends: its turn flies
        if self.loiter is not None:
            self._schedule_loiter(world, turning)
            self._begin_loiter(world, moving & (self._loiter_at == world.steps[:, None]))
        for repeat in np.unique(self.repeats):
            due = moving & (world.steps[:, None] % repeat == 0) & (self.repeats[None, :] == repeat)
            if due.any():
                self._decide(world, proposed, due, int(repeat))
        if self.loiter is not None:
            self._fly_loiter(world, moving & (self._loiter_sign != 0))
        self._begin_hold(world, moving & self._engaged & (self._hold_at == world.steps[:, None]))
        self._fly_hold(world, moving & self._holding)
        self.counts.flown_steps += moving
        self.counts.backup_steps += moving & self._engaged
        self.counts.adjusted_steps += moving & self._adjusted
        self.counts.held_steps += moving & self._holding
        self.counts.unprotected_steps += moving & self._unprotected
        return np.where(moving[..., None], self._flying, proposed)

    def _wind(self, world: World) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) each vehicle's wind, east and north (m/s)."""
        east, north = world.wind_m_s()
        return np.repeat(east[:, None], N_ROLES, axis=1), np.repeat(north[:, None], N_ROLES, axis=1)

    def _prediction(self, world: World, flat: np.ndarray, speeds: np.ndarray) -> Prediction:
        varied = self.airframes
        if varied is None:
            return KINEMATIC
        wind = None
        if self.loiter is not None:
            east, north = self._wind(world)
            wind = self.loiter.wind(east.reshape(-1)[flat], north.reshape(-1)[flat], speeds)
        return LaggedPrediction(varied.airframe(flat), varied.lag_state(flat), wind)

    def _over_the_ground(
        self, world: World, w: np.ndarray, j: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Vehicles (w, j): their wind (east, north), airspeed, ground velocity (gx, gy) and turn-rate limit."""
        east, north = (wind[w, j] for wind in self._wind(world))
        v, phi = world.v_m_s[w, j], world.phi_rad[w, j]
        limit = np.broadcast_to(world.c.turn_rate_max_rad_s, (world.n, N_ROLES))[w, j]
        return east, north, v, v * np.cos(phi) + east, v * np.sin(phi) + north, limit

    def _schedule_loiter(self, world: World, turning: np.ndarray) -> None:
        """The ``turning`` (N, 3) vehicles' backups end their lead now: their loiter starts after the turn-in (now, if
        there is none)."""
        assert self.loiter is not None
        self._loiter_at[turning] = np.broadcast_to(world.steps[:, None], turning.shape)[turning]
        self._loiter_at[turning] += self.loiter.turn_in_steps(world.c.dt_s)

    def _begin_loiter(self, world: World, starting: np.ndarray) -> None:
        """Fix the loiter's circle of the ``starting`` (N, 3) vehicles from their states: their backup's turn-in
        ends."""
        if not starting.any():
            return
        assert self.loiter is not None
        w, j = np.nonzero(starting)
        backup = self.memory.backup.reshape(world.n, N_ROLES)[w, j]
        sign = np.where(backup % N_TURNS == 0, 1.0, -1.0)
        _, _, v, gx, gy, limit = self._over_the_ground(world, w, j)
        radius = self.loiter.radius_m(v, limit)
        cx, cy = loiter_centre(world.x_m[w, j], world.y_m[w, j], gx, gy, sign, radius)
        self._loiter_sign[w, j] = sign
        self._loiter_centre[w, j] = np.stack([cx, cy], axis=-1)
        self._loiter_radius[w, j] = radius

    def _fly_loiter(self, world: World, loitering: np.ndarray) -> None:
        """This step's command of the ``loitering`` (N, 3) vehicles: the loiter law's heading rate, the speed held."""
        if not loitering.any():
            return
        assert self.loiter is not None
        w, j = np.nonzero(loitering)
        east, north, _, gx, gy, limit = self._over_the_ground(world, w, j)
        centre = self._loiter_centre[w, j]
        circle = (centre[:, 0], centre[:, 1], self._loiter_radius[w, j], self._loiter_sign[w, j])
        x, y = world.x_m[w, j], world.y_m[w, j]
        self._flying[w, j] = loiter_action(x, y, gx, gy, east, north, circle, limit, self.loiter.law)

    def _begin_hold(self, world: World, starting: np.ndarray) -> None:
        """Fix the held line of the ``starting`` (N, 3) vehicles: through where each is, along the course its backup's
        check predicted for this moment (:attr:`Memory.held_course`)."""
        if not starting.any():
            return
        w, j = np.nonzero(starting)
        course = self.memory.held_course.reshape(world.n, N_ROLES)[w, j]
        self._line[w, j] = np.stack([world.x_m[w, j], world.y_m[w, j], course], axis=-1)
        self._holding[w, j] = True
        self._hold_at[w, j] = -1

    def _fly_hold(self, world: World, holding: np.ndarray) -> None:
        """This step's command of the ``holding`` (N, 3) vehicles: the line law's heading rate, the lead's speed
        command kept."""
        if not holding.any():
            return
        w, j = np.nonzero(holding)
        east, north, _, gx, gy, limit = self._over_the_ground(world, w, j)
        line = self._line[w, j]
        rate = line_turn_rate(
            world.x_m[w, j], world.y_m[w, j], gx, gy, (line[:, 0], line[:, 1], line[:, 2]), limit, self.line_law
        )
        self._flying[w, j, 0] = rate / limit

    def _schedule_hold(self, world: World, w: np.ndarray, j: np.ndarray, d: Decision, started: np.ndarray) -> None:
        """The vehicles (w, j) decided now: a backup that started now with a held lead holds its course from the end
        of the lead's open part; one that stopped flying, or whose lead has ended (its turn flies), holds nothing."""
        done = ~d.engaged | (d.straight_steps == 0)
        self._holding[w[done], j[done]] = False
        self._hold_at[w[done], j[done]] = -1
        if self.airframes is None:
            return
        held_from = self.airframes.held_from_steps(world.c.dt_s)
        course = d.memory.held_course
        new = started & np.isfinite(course)
        if held_from is None or not new.any():
            return
        self._holding[w[new], j[new]] = False
        self._hold_at[w[new], j[new]] = world.steps[w[new]] + held_from

    def _decide(self, world: World, proposed: np.ndarray, due: np.ndarray, steps: int) -> Decision:
        flat = np.flatnonzero(due.reshape(-1))
        before = self.memory.select(flat)
        state = np.stack([world.x_m, world.y_m, world.v_m_s, world.phi_rad], axis=-1).reshape(-1, 4)[flat]
        prediction = self._prediction(world, flat, state[:, 2])
        d = decide(
            state,
            proposed.reshape(-1, 2)[flat],
            self.memory.select(flat),
            self.hazards(world).select(flat),
            self.limits.select(flat),
            world.c.dt_s,
            steps,
            self.cfg.margin_m,
            self.cfg,
            error=None if self.decision_error is None else self.decision_error.rows(len(flat)),
            prediction=prediction,
        )
        self.memory = self.memory.merged(flat, d.memory)
        w, j = np.unravel_index(flat, due.shape)
        self._flying[w, j] = d.action
        self._turn[w, j] = d.turn
        self._turn_at[w, j] = np.where(d.straight_steps < steps, world.steps[w] + d.straight_steps, -1)
        self._engaged[w, j] = d.engaged
        self._adjusted[w, j] = d.adjusted
        self._unprotected[w, j] = d.unprotected
        self.counts.interventions[w, j] += d.engaged_now
        self.counts.switches[w, j] += d.engaged_now.astype(np.int64) + d.released_now
        # A backup starts now when the monitor engages, or when a vehicle without a known backup takes a new one.
        self._schedule_hold(world, w, j, d, d.engaged & (~before.engaged | ~before.protected))
        if self.loiter is not None:
            self._loiter_sign[w[~d.engaged], j[~d.engaged]] = 0.0
            self._loiter_at[w[~d.engaged], j[~d.engaged]] = -1
            turning = np.zeros(due.shape, dtype=bool)
            turning[w, j] = d.engaged & (d.straight_steps == 0) & (self._loiter_at[w, j] < 0)
            self._schedule_loiter(world, turning)
            self._begin_loiter(world, turning & (self._loiter_at == world.steps[:, None]))
        return d


class VehicleMonitor:
    """The monitor for one vehicle (a companion computer): the same :func:`decide`, M = 1, with the margin
    and the pending commands the caller measures (Kalman covariance, link latency)."""

    def __init__(self, state: WorldState, role_index: int, cfg: ShieldConfig) -> None:
        if state.n != 1:
            raise ValueError(f"a vehicle monitor watches one world, got {state.n}")
        c = state.c
        self.cfg = cfg
        self.dt_s = c.dt_s
        self.hazards = Hazards(state.radar_m.copy(), state.radar_r_m.copy(), c.area_m)
        j = role_index
        self.limits = Limits(
            c.speed_min_m_s[j : j + 1],
            c.speed_max_m_s[j : j + 1],
            c.turn_rate_max_rad_s[j : j + 1],
            c.accel_max_m_s2[j : j + 1],
        )
        self.memory = Memory.initial(1)

    def reset(self) -> None:
        self.memory = Memory.initial(1)

    def decide(
        self,
        x_m: float,
        y_m: float,
        v_m_s: float,
        phi_rad: float,
        proposed: np.ndarray,
        steps: int,
        margin_m: float,
        pending: np.ndarray | None = None,
        error: EstimateError | None = None,
        prediction: Prediction = KINEMATIC,
    ) -> Decision:
        """One decision: the action to fly for the next ``steps`` steps and whether the backup flies (``prediction``:
        how the paths are predicted, eq. 5 unless the airframe's response is given)."""
        state = np.array([[x_m, y_m, v_m_s, phi_rad]])
        queue = None if pending is None else np.asarray(pending, dtype=np.float64).reshape(1, -1, 2)
        d = decide(
            state,
            np.asarray(proposed, dtype=np.float64).reshape(1, 2),
            self.memory,
            self.hazards,
            self.limits,
            self.dt_s,
            steps,
            margin_m,
            self.cfg,
            queue,
            error,
            prediction,
        )
        self.memory = d.memory
        return d
