"""The simulated world: kinematics (eq. 5-6), mission logic (eq. 9, Table 1) and hazard cost (eq. 11).

One source of truth for physics and mission logic, used by training, evaluation and the SITL
vehicles. Pure numpy and batched: a :class:`World` holds N independent worlds of three UAVs each, and
one :meth:`World.step` advances all of them with a handful of array operations.

Frames and units: x east, y north in metres from the area's south-west corner; heading phi in radians,
counter-clockwise from east (eq. 5's frame); speed v in m/s. Vehicle index = role order
(decoy, detect, strike).

Kinematics (eq. 5) are integrated exactly over a step for a constant turn rate (the arc of a circle at
the step's mean speed), so a constant-rate circle closes on itself and a straight flight is exact:

    v'   = clip(v + u dt, v_min, v_max)                  (eq. 6 speed bounds; v_m = (v + v') / 2)
    phi' = phi + omega dt
    x'   = x + v_m dt sinc(omega dt / 2) cos(phi + omega dt / 2)   (x' = v cos phi integrated)
    y'   = y + v_m dt sinc(omega dt / 2) sin(phi + omega dt / 2)   (y' = v sin phi integrated)

(sinc(a) = sin(a) / a: the chord of the arc; exact for omega = 0 too).

With a scenario ``wind:`` the air mass moves every vehicle by the wind's velocity as well (v and phi are then the
airspeed and the heading); calm air is eq. 5 exactly. :meth:`World.step` is :meth:`World.integrate` followed by
:meth:`World.mission_step`: the SITL swaps the first half for another dynamics model (:meth:`World.set_states`).

Mission logic (DESIGN.md section 2, eq. 9 read as simultaneous conditions), D_i = distance of UAV i
from the SAM:
    SAM radar on     <=> R3 < D1 <= R4                    (decoy holds its ring; not latched)
    identified       latched once radar on and R1 < D2 <= R2
    hit              identified, radar on, R1 < D2 <= R2 and D3 < R1, all at once -> mission success
Leaving the area (eq. 6 position bounds) terminates the world; so does the hit. The episode cap
truncates it. Cost (eq. 11): 1 per step for a UAV inside any radar's radius, else 0.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from tssac_core.sim.scenario import ROLES, Layout, Role, Scenario

KM = 1000.0
N_ROLES = len(ROLES)


def constant_operand(value: float) -> np.ndarray:
    """A constant operand as a 0-d array. numpy converts a Python float into an array on every call (about
    0.5 us, most of a small-N operation); a 0-d array it takes as is, on its fast path."""
    return np.array(value)


@functools.lru_cache(maxsize=64, typed=True)
def cached_constant(value: float) -> np.ndarray:
    """:func:`constant_operand` made once per value, for scenario constants (the lookup costs less than a
    fresh 0-d array). Shared: read it, never write into it."""
    return constant_operand(value)


_ZERO, _HALF, _ONE, _MINUS_ONE = (
    constant_operand(0.0),
    constant_operand(0.5),
    constant_operand(1.0),
    constant_operand(-1.0),
)
_SINC_C3, _SINC_C5 = constant_operand(1.0 / 6.0), constant_operand(1.0 / 120.0)
_WRAP_EDGES = np.array([-math.pi, math.pi])
"""Heading bins: below -pi, [-pi, pi), at or above pi (``searchsorted(side="right")`` gives 0, 1, 2)."""
_WRAP_SHIFT = np.array([2 * math.pi, -0.0, -2 * math.pi])
"""What each heading bin adds: x + (-0.0) is x to the bit (even for -0.0), x + (-2 pi) is x - 2 pi."""


@dataclass(frozen=True)
class WorldConstants:
    """Per-scenario constants in SI units, per role where they differ (arrays of shape (3,))."""

    dt_s: float
    area_m: float
    episode_steps: int
    r1_m: float
    r2_m: float
    r3_m: float
    r4_m: float
    speed_min_m_s: np.ndarray
    speed_max_m_s: np.ndarray
    speed_init_m_s: np.ndarray
    turn_rate_max_rad_s: np.ndarray
    accel_max_m_s2: np.ndarray
    zone_inner_m: np.ndarray
    """Each role's zone is inner < D <= outer (strike: D < R1, so inner = -inf)."""
    zone_outer_m: np.ndarray

    @staticmethod
    def from_scenario(s: Scenario) -> WorldConstants:
        specs = [s.vehicle(role) for role in ROLES]
        r = s.ranges
        r1, r2, r3, r4 = (r.strike_launch_km * KM, r.detect_km * KM, r.sam_launch_km * KM, r.sam_detect_km * KM)
        return WorldConstants(
            dt_s=s.dt_s,
            area_m=s.area_km * KM,
            episode_steps=s.episode_steps,
            r1_m=r1,
            r2_m=r2,
            r3_m=r3,
            r4_m=r4,
            speed_min_m_s=np.array([v.speed_min_m_s for v in specs]),
            speed_max_m_s=np.array([v.speed_max_m_s for v in specs]),
            speed_init_m_s=np.array([v.speed_init_m_s for v in specs]),
            turn_rate_max_rad_s=np.radians([v.turn_rate_max_deg_s for v in specs]),
            accel_max_m_s2=np.array([v.accel_max_m_s2 for v in specs]),
            zone_inner_m=np.array([r3, r1, -np.inf]),
            # D3 < R1 is strict: the largest float below R1 makes "<=" mean "<".
            zone_outer_m=np.array([r4, r2, np.nextafter(r1, 0.0)]),
        )


@dataclass
class StepResult:
    """What one step did, per world (N,) or per world and vehicle (N, 3)."""

    cost: np.ndarray
    """Eq. 11 cost of this step, (N, 3) float."""
    zone_dist_prev_m: np.ndarray
    """Distance to the role's zone before the step, (N, 3)."""
    zone_dist_m: np.ndarray
    """Distance to the role's zone after the step (0 inside it), (N, 3)."""
    in_zone: np.ndarray
    """Vehicle holds its zone after the step, (N, 3) bool."""
    task_completed: np.ndarray
    """The role's task was completed for the first time this step, (N, 3) bool (eq. 9)."""
    out_of_area: np.ndarray
    """Vehicle left the area this step, (N, 3) bool."""
    hazard_entered: np.ndarray
    """Vehicle entered a radar's disk this step, (N, 3) bool."""
    radar_on_changed: np.ndarray
    """The SAM radar switched on or off this step, (N,) bool (the new state is World.radar_on)."""
    identified_now: np.ndarray
    """The target was identified this step, (N,) bool."""
    hit_now: np.ndarray
    """The target was hit this step (mission success), (N,) bool."""
    terminated: np.ndarray
    """The world ended this step by a hit or a vehicle leaving the area, (N,) bool."""
    truncated: np.ndarray
    """The world reached the episode cap this step without terminating, (N,) bool."""
    moving: np.ndarray
    """Vehicles that took the step (active, in a running world), (N, 3) bool."""


class World:
    """N worlds of three UAVs, stepped together.

    State arrays (public, read them freely; write only through reset/step): ``x_m, y_m, v_m_s,
    phi_rad`` (N, 3); layout ``sam_m`` (N, 2), ``target_m`` (N, 2), ``radar_m`` (N, K, 2),
    ``radar_r_m`` (N, K); flags ``active`` (N, 3) (inactive vehicles are parked: they neither move
    nor count), ``running`` (N,) (a finished world is frozen until reset), ``radar_on``,
    ``identified``, ``hit`` (N,), ``task_done`` (N, 3), ``in_hazard`` (N, 3), ``steps`` (N,),
    ``cost_total`` (N, 3).

    Speed (benchmarks/bench_env.py): a step is a fixed sequence of whole-array operations, so its cost
    is the number of numpy calls at small N and the number of passes over memory at large N. Two
    choices keep both low without changing a single bit of the arithmetic:

    - positions live in one (2, N, 3) array (``x_m``, ``y_m`` are views of it), so the chord update,
      the SAM distance, the radar test and the area bounds treat x and y in one call each;
    - every per-role constant and every per-layout position (SAM, radars, radar radii squared) is kept
      broadcast to the full (N, 3) vehicle shape (rebuilt by :meth:`reset`). An (N, 3) operand against
      an (N, 1) or (3,) one makes numpy run N inner loops of 3 elements, several times slower than one
      loop over 3N; same-shape operands avoid that.

    At N = 1 the same choice pays for another reason: numpy runs an operation whose operands are all
    contiguous arrays of one shape and one dtype (or 0-d arrays) on a fast path (about 0.7 us); a
    broadcast, a strided view, a bool operand in float arithmetic (a cast) or a ``where=`` takes its
    general iterator (2.5-3.5 us). So constants are 0-d arrays (:func:`constant_operand`), masks are turned into
    floats once, and a broadcast is split into same-shape calls where that takes fewer microseconds. And an
    operation that writes into one of its inputs takes the slow path when the array has a single element,
    as every per-world (N,) array has at N = 1: those are built afresh (``a = a | b``, not ``a |= b``).
    """

    def __init__(self, scenario: Scenario, n: int, max_radars: int | None = None) -> None:
        self.scenario = scenario
        self.c = WorldConstants.from_scenario(scenario)
        self.n = n
        k = max_radars if max_radars is not None else _max_radar_count(scenario)
        self._xy = np.zeros((2, n, N_ROLES))
        self.v_m_s = np.zeros((n, N_ROLES))
        self.phi_rad = np.zeros((n, N_ROLES))
        self.sam_m = np.zeros((n, 2))
        self.target_m = np.zeros((n, 2))
        # Unused radar slots sit far outside the area with zero radius: they never cost anything.
        self.radar_m = np.full((n, k, 2), -1e9)
        self.radar_r_m = np.zeros((n, k))
        self.active = np.zeros((n, N_ROLES), dtype=bool)
        self.running = np.zeros(n, dtype=bool)
        self.radar_on = np.zeros(n, dtype=bool)
        self.identified = np.zeros(n, dtype=bool)
        self.hit = np.zeros(n, dtype=bool)
        self.task_done = np.zeros((n, N_ROLES), dtype=bool)
        self.in_hazard = np.zeros((n, N_ROLES), dtype=bool)
        self.steps = np.zeros(n, dtype=np.int64)
        self.cost_total = np.zeros((n, N_ROLES))
        self.zone_dist_m = np.zeros((n, N_ROLES))
        self.sam_dist_m = np.zeros((n, N_ROLES))
        self._small_turns = float(self.c.turn_rate_max_rad_s.max()) * self.c.dt_s / 2 < 0.05
        self._wind_xy: np.ndarray | None = None
        """The wind's (east, north) velocity as (2, 1, 1) or per world (2, N, 1), or None in calm air (no drift: eq.
        5 exactly)."""
        self.set_wind(None)
        self.layout_id = np.full(n, -1, dtype=np.int64)
        """Changes whenever a world gets a new layout (lets controllers cache per-layout work)."""
        self._resets = 0
        self._build_constants()

    # Positions are views of one (2, N, 3) array; assigning to x_m / y_m writes into it.
    @property
    def xy_m(self) -> np.ndarray:
        """Positions stacked, (2, N, 3): ``xy_m[0]`` is x_m, ``xy_m[1]`` is y_m (read only, as they are)."""
        return self._xy

    @property
    def x_m(self) -> np.ndarray:
        return self._xy[0]

    @x_m.setter
    def x_m(self, value: np.ndarray) -> None:
        self._xy[0] = value

    @property
    def y_m(self) -> np.ndarray:
        return self._xy[1]

    @y_m.setter
    def y_m(self, value: np.ndarray) -> None:
        self._xy[1] = value

    @property
    def sam_xy_m(self) -> np.ndarray:
        """The SAM's position per vehicle, (2, N, 3), x over y (read only): same-shape operand for ``xy_m``."""
        return self._sam_xy

    @property
    def points_xy_m(self) -> np.ndarray:
        """The layout's points per world, (2, N, 2 + K), x over y: the target, the SAM, then the radar slots
        (read only; what the observation measures ranges and bearings to, rebuilt at reset)."""
        return self._points_xy

    @property
    def has_unused_radar_slots(self) -> bool:
        """Some world's layout has fewer radars than the world holds (their slots have radius 0)."""
        return self._unused_slots

    @property
    def max_radars(self) -> int:
        return self.radar_r_m.shape[1]

    @property
    def layout_token(self) -> object:
        """A new object whenever any world gets a new layout (reset) or this World is rebuilt (unpickled): while it
        is the same object, so are the layout arrays (caches of per-layout work compare it)."""
        return self._layout_token

    @property
    def layout_version(self) -> int:
        """Grows whenever any world gets a new layout (reset): one number to compare instead of ``layout_id``."""
        return self._resets

    def _build_constants(self) -> None:
        """Per-role constants broadcast to (N, 3) and the per-layout arrays of every world."""
        c, shape = self.c, (self.n, N_ROLES)
        self._turn_rate = np.broadcast_to(c.turn_rate_max_rad_s, shape).copy()
        self._accel = np.broadcast_to(c.accel_max_m_s2, shape).copy()
        self._speed_min = np.broadcast_to(c.speed_min_m_s, shape).copy()
        self._speed_max = np.broadcast_to(c.speed_max_m_s, shape).copy()
        self._zone_inner = np.broadcast_to(c.zone_inner_m, shape).copy()
        self._zone_outer = np.broadcast_to(c.zone_outer_m, shape).copy()
        self._rate = np.stack([self._turn_rate, self._accel])
        """Turn-rate over acceleration limit, (2, N, 3), to scale the (omega, u) actions in one call."""
        self._dt = constant_operand(c.dt_s)
        self._half_area = constant_operand(0.5 * c.area_m)
        self._episode_steps = constant_operand(c.episode_steps)
        k = self.max_radars
        self._trig = np.zeros((2, *shape))
        """Scratch for the chord's (cos, sin) in a step, (2, N, 3)."""
        self._sam_xy = np.zeros((2, *shape))
        """SAM position per vehicle, (2, N, 3)."""
        self._radar_xy = np.zeros((2, k, *shape))
        """Radar positions per vehicle, (2, K, N, 3)."""
        self._radar_r2: dict[float, np.ndarray] = {}
        """Squared radar radius (plus a margin, the key) per vehicle, (K, N, 3)."""
        self._points_xy = np.zeros((2, self.n, 2 + k))
        """Target, SAM and radar positions, (2, N, 2 + K)."""
        self._unused_slots = False
        self._cache_layouts(np.arange(self.n))
        self._layout_token = object()
        self._update_moving()

    def _cache_layouts(self, idx: np.ndarray) -> None:
        """Refresh the broadcast layout arrays of worlds ``idx`` from sam_m, radar_m and radar_r_m."""
        self._sam_xy[:, idx] = self.sam_m[idx].T[:, :, None]
        self._radar_xy[:, :, idx] = self.radar_m[idx].transpose(2, 1, 0)[..., None]
        self._points_xy[:, idx, 0] = self.target_m[idx].T
        self._points_xy[:, idx, 1] = self.sam_m[idx].T
        self._points_xy[:, idx, 2:] = self.radar_m[idx].transpose(2, 0, 1)
        self._unused_slots = bool(np.any(self.radar_r_m <= 0))
        for margin, r2 in self._radar_r2.items():
            r2[:, idx] = self._squared_radius(idx, margin).T[..., None]
        if 0.0 not in self._radar_r2:
            self._radar_r2[0.0] = self._squared_radius_full(0.0)

    def _squared_radius(self, idx: np.ndarray | slice, margin_m: float) -> np.ndarray:
        """(n, K) squared radius of each radar's disk inflated by ``margin_m`` (unused slots: 0)."""
        r = self.radar_r_m[idx]
        if margin_m:  # unused slots have radius 0: they stay empty whatever the margin
            r = np.where(r > 0, r + margin_m, 0.0)
        return r**2

    def _squared_radius_full(self, margin_m: float) -> np.ndarray:
        r2 = self._squared_radius(slice(None), margin_m)  # (N, K)
        return np.ascontiguousarray(np.broadcast_to(r2.T[..., None], (self.max_radars, self.n, N_ROLES)))

    def __getstate__(self) -> dict:
        # The broadcast arrays are derived; a pickle holds the state only (and stays small).
        state = self.__dict__.copy()
        for key in (
            "_turn_rate",
            "_accel",
            "_speed_min",
            "_speed_max",
            "_zone_inner",
            "_zone_outer",
            "_rate",
            "_dt",
            "_half_area",
            "_episode_steps",
            "_trig",
            "_sam_xy",
            "_radar_xy",
            "_radar_r2",
            "_points_xy",
            "_unused_slots",
            "_layout_token",
            "_moving",
            "_dt_moving",
            "_running_steps",
            "_running_count",
        ):
            state.pop(key, None)
        return state

    def __setstate__(self, state: dict) -> None:
        if "_xy" not in state:  # pickled before positions were stacked: separate x_m and y_m arrays
            state["_xy"] = np.stack([state.pop("x_m"), state.pop("y_m")])
        state.setdefault("_wind_xy", None)  # pickled before wind existed: calm air
        self.__dict__.update(state)
        self._build_constants()

    def reset(
        self, index: np.ndarray | list[int], layouts: list[Layout], active: tuple[bool, ...] = (True, True, True)
    ) -> None:
        """Start worlds ``index`` afresh with the given layouts (one per index)."""
        idx = np.asarray(index, dtype=np.int64)
        if len(idx) != len(layouts):
            raise ValueError(f"{len(idx)} worlds but {len(layouts)} layouts")
        for i, lay in zip(idx, layouts):
            if len(lay.radars) > self.max_radars:
                raise ValueError(f"layout has {len(lay.radars)} radars; this world holds {self.max_radars}")
            self.sam_m[i] = np.multiply(lay.sam_km, KM)
            self.target_m[i] = np.multiply(lay.target_km, KM)
            self.radar_m[i] = -1e9
            self.radar_r_m[i] = 0.0
            for k, radar in enumerate(lay.radars):
                self.radar_m[i, k] = np.multiply(radar.position_km, KM)
                self.radar_r_m[i, k] = radar.radius_km * KM
            for j, role in enumerate(ROLES):
                start = lay.starts[role.value]
                self.x_m[i, j] = start.position_km[0] * KM
                self.y_m[i, j] = start.position_km[1] * KM
                self.phi_rad[i, j] = wrap_angle(math.radians(start.heading_deg))
        self._cache_layouts(idx)
        self.layout_id[idx] = self._resets + np.arange(len(idx))
        self._resets += len(idx)
        self._layout_token = object()
        self.v_m_s[idx] = self.c.speed_init_m_s
        self.active[idx] = active
        self.running[idx] = True
        self.radar_on[idx] = False
        self.identified[idx] = False
        self.hit[idx] = False
        self.task_done[idx] = False
        self.steps[idx] = 0
        self.cost_total[idx] = 0.0
        self.sam_dist_m[idx] = np.hypot(self.x_m[idx] - self.sam_m[idx, 0:1], self.y_m[idx] - self.sam_m[idx, 1:2])
        self.zone_dist_m[idx] = _zone_distance(self.sam_dist_m[idx], self.c.zone_inner_m, self.c.zone_outer_m)
        self.in_hazard[idx] = self._inside_radar(idx) & self.active[idx]
        self._update_moving()

    def _update_moving(self) -> None:
        """Which vehicles the next step moves (active, in a running world), as a mask and as each one's time
        step (dt, or 0: parked vehicles and finished worlds do not move; the mask as floats once, since a bool
        operand is cast on every call). Kept between steps: they change only when a world starts or ends,
        which a count of the running worlds tells (``running`` only loses worlds in a step)."""
        self._moving = self.active & self.running[:, None]
        dt = self._moving.astype(np.float64)
        dt *= self._dt
        self._dt_moving = dt
        self._running_steps = self.running.astype(np.int64)  # what a step adds to ``steps``
        self._running_count = np.count_nonzero(self.running)

    def step(self, action: np.ndarray) -> StepResult:
        """Advance every running world by dt; ``action`` is (N, 3, 2) in [-1, 1]: [omega, u] scaled to the limits
        (eq. 8). The two halves of the seam: :meth:`integrate` (eq. 5-6), then :meth:`mission_step`."""
        self.integrate(action)
        return self.mission_step()

    def integrate(self, action: np.ndarray) -> None:
        """Eq. 5-6 for every moving vehicle over dt (``action`` as in :meth:`step`), and the scenario's wind drift;
        the mission is not judged until :meth:`mission_step`."""
        self._move(action, self._dt_moving)
        if self._wind_xy is not None:
            self._xy += self._wind_xy * self._dt_moving  # the air mass carries the vehicles (x' = v cos phi + w_x)

    def set_wind(self, extra_m_s: np.ndarray | None) -> None:
        """The wind the vehicles drift in: the scenario's, plus ``extra_m_s`` (2, N) per world (east, north; m/s), e.g.
        a wind drawn per episode (:mod:`tssac_core.sim.varied_airframes`); None: the scenario's alone."""
        wind = self.scenario.wind.velocity_m_s() if self.scenario.wind is not None else (0.0, 0.0)
        if extra_m_s is None:
            self._wind_xy = None if wind == (0.0, 0.0) else np.array(wind)[:, None, None]
        else:
            self._wind_xy = (np.asarray(extra_m_s, dtype=np.float64) + np.array(wind)[:, None])[:, :, None]

    def wind_m_s(self) -> np.ndarray:
        """(2, N) each world's wind (east, north; m/s): the scenario's and any drawn per episode; zeros in calm air."""
        if self._wind_xy is None:
            return np.zeros((2, self.n))
        return np.broadcast_to(self._wind_xy[:, :, 0], (2, self.n)).copy()

    def set_states(self, x_m: np.ndarray, y_m: np.ndarray, v_m_s: np.ndarray, phi_rad: np.ndarray) -> None:
        """Vehicle states after dt from another dynamics model (the SITL's JSBSim airframes), (N, 3) each: the ground
        position, the ground speed and the course (eq. 5's v and phi of the path flown). Parked vehicles and finished
        worlds keep theirs. Call :meth:`mission_step` next."""
        moving = self._moving
        self._xy[0] = np.where(moving, x_m, self._xy[0])
        self._xy[1] = np.where(moving, y_m, self._xy[1])
        self.v_m_s = np.where(moving, v_m_s, self.v_m_s)
        phi = np.where(moving, phi_rad, self.phi_rad)
        phi += _WRAP_SHIFT.take(_WRAP_EDGES.searchsorted(phi, side="right"))  # eq. 6 heading bounds, x itself inside
        self.phi_rad = phi

    def mission_step(self) -> StepResult:
        """Mission logic (eq. 9) and cost (eq. 11) on the vehicles' states after a move (:meth:`integrate` or
        :meth:`set_states`); counts the step and ends the worlds that ended."""
        moving = self._moving
        zone_dist_prev = self.zone_dist_m
        in_zone = self._measure_zones(moving)
        flags = self._mission_logic(in_zone)
        cost, hazard_entered = self._hazard_cost(moving)
        out = self._out_of_area(moving)
        terminated, truncated = self._end_worlds(flags[3], out)
        return StepResult(
            moving=moving,
            cost=cost,
            zone_dist_prev_m=zone_dist_prev,
            zone_dist_m=self.zone_dist_m,
            in_zone=in_zone,
            task_completed=flags[0],
            out_of_area=out,
            hazard_entered=hazard_entered,
            radar_on_changed=flags[1],
            identified_now=flags[2],
            hit_now=flags[3],
            terminated=terminated,
            truncated=truncated,
        )

    def _move(self, action: np.ndarray, dt: np.ndarray) -> None:
        """Eq. 5-6 for every vehicle: speed first (clipped to its bounds), then the exact arc at the step's mean
        speed; ``dt`` (N, 3) is each vehicle's time step (0 for those that do not move)."""
        # (omega, u) clipped and scaled as (2, N, 3): one C-ordered copy of the (N, 3, 2) actions transposed,
        # then same-shape contiguous operands (an operation reading the strided view is slower than the copy).
        a = action.transpose(2, 0, 1).copy()
        np.maximum(a, _MINUS_ONE, out=a)
        np.minimum(a, _ONE, out=a)
        a *= self._rate
        theta, dv = a[0], a[1]
        theta *= dt
        dv *= dt
        v_new = np.add(self.v_m_s, dv)
        np.maximum(v_new, self._speed_min, out=v_new)  # eq. 6 speed bounds
        np.minimum(v_new, self._speed_max, out=v_new)
        # The chord of an arc of angle theta has length v dt sinc(theta / 2) along phi + theta / 2.
        half = theta * _HALF
        chord = self.v_m_s + v_new
        chord *= _HALF
        chord *= dt
        chord *= self._sinc(half)
        trig = self._trig
        np.add(self.phi_rad, half, out=half)  # the chord's direction (half is not needed any more)
        np.cos(half, out=trig[0])
        np.sin(half, out=trig[1])
        for component in trig:  # x and y in two same-shape calls (one broadcast call costs more at small N)
            component *= chord
        self._xy += trig  # x' = x + chord cos(mid), y' = y + chord sin(mid)
        self.v_m_s = v_new
        # |theta| <= 90 deg/s * 1 s < pi (scenario limits), so one wrap either way suffices (eq. 6 heading
        # bounds): -2 pi at or above pi, +2 pi below -pi, as two masked subtractions would, in one lookup.
        phi = self.phi_rad + theta
        phi += _WRAP_SHIFT.take(_WRAP_EDGES.searchsorted(phi, side="right"))
        self.phi_rad = phi

    def _measure_zones(self, moving: np.ndarray) -> np.ndarray:
        """Distances to the SAM and to each role's zone after the move; returns in_zone (N, 3)."""
        d = self._xy - self._sam_xy
        d *= d
        sam_dist = np.add(d[0], d[1])
        np.sqrt(sam_dist, out=sam_dist)
        self.sam_dist_m = sam_dist
        self.zone_dist_m = _zone_distance(sam_dist, self._zone_inner, self._zone_outer)
        in_zone = sam_dist > self._zone_inner
        in_zone &= sam_dist <= self._zone_outer
        in_zone &= moving
        return in_zone

    def _mission_logic(self, in_zone: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Eq. 9 (Table 1), all conditions at once. Returns (task_completed, radar_on_changed, identified_now,
        hit_now)."""
        radar_on = in_zone[:, 0]
        radar_on_changed = radar_on != self.radar_on
        self.radar_on = radar_on
        seen = radar_on & in_zone[:, 1]  # the detect UAV holds its ring while the radar is on
        # Per-world (N,) flags are built afresh, not in place (see the class docstring).
        identified_now = _and_not(seen, self.identified)
        self.identified = self.identified | identified_now
        hit_now = seen & in_zone[:, 2]
        hit_now = hit_now & self.identified
        hit_now = _and_not(hit_now, self.hit)
        self.hit = self.hit | hit_now
        task_completed = _and_not(in_zone, self.task_done)  # the decoy's task: first time in its ring
        task_completed[:, 1] = identified_now
        task_completed[:, 2] = hit_now
        self.task_done |= task_completed
        return task_completed, radar_on_changed, identified_now, hit_now

    def _hazard_cost(self, moving: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 11 cost of the step and which vehicles entered a radar's disk."""
        inside = self._inside_all(self._radar_r2[0.0])
        inside &= moving
        hazard_entered = _and_not(inside, self.in_hazard)
        self.in_hazard = inside
        cost = inside.astype(np.float64)
        self.cost_total += cost
        return cost, hazard_entered

    def _out_of_area(self, moving: np.ndarray) -> np.ndarray:
        """Eq. 6 position bounds: max(|x - A/2|, |y - A/2|) > A/2 for a moving vehicle."""
        h = self._half_area
        off = self._xy - h
        np.abs(off, out=off)
        out = np.maximum(off[0], off[1]) > h
        out &= moving
        return out

    def _end_worlds(self, hit_now: np.ndarray, out: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Count the step; a hit or a vehicle leaving ends a world, the episode cap truncates it."""
        # Per-world (N,) arrays are built afresh, not in place (see the class docstring).
        self.steps = self.steps + self._running_steps  # the worlds that took this step count it
        terminated = hit_now | _any_vehicle(out)
        terminated = terminated & self.running
        self.running = _and_not(self.running, terminated)
        truncated = self.steps >= self._episode_steps
        truncated = truncated & self.running
        self.running = _and_not(self.running, truncated)
        if np.count_nonzero(self.running) != self._running_count:
            self._update_moving()
        return terminated, truncated

    def near_radar(self, margin_m: float) -> np.ndarray:
        """(N, 3): each vehicle lies within ``margin_m`` of a radar's disk (inside radius + margin).

        With margin 0 this is the eq. 11 hazard; training may use a margin as a tightened constraint
        (:class:`tssac_core.sim.env.RoleTask`).
        """
        margin_m = float(margin_m)
        r2 = self._radar_r2.get(margin_m)
        if r2 is None:  # the first call with this margin: keep its radii for the next steps
            r2 = self._radar_r2[margin_m] = self._squared_radius_full(margin_m)
        return self._inside_all(r2)

    def _inside_all(self, r2: np.ndarray) -> np.ndarray:
        """(N, 3): inside any radar's disk of squared radius ``r2`` (K, N, 3): dx^2 + dy^2 < r^2."""
        d = self._xy[:, None] - self._radar_xy  # (2, K, N, 3)
        d *= d
        return _any_radar(np.add(d[0], d[1]) < r2)

    def _inside_radar(self, idx: np.ndarray) -> np.ndarray:
        """(n, 3) for worlds ``idx`` (reset): inside any radar's disk."""
        d = self._xy[:, idx][:, None] - self._radar_xy[:, :, idx]
        d *= d
        return _any_radar(np.add(d[0], d[1]) < self._radar_r2[0.0][:, idx])

    def _sinc(self, half: np.ndarray) -> np.ndarray:
        """sin(h) / h; a Taylor series when every |h| is small (error < h^6 / 5040, under 1e-12)."""
        if self._small_turns:
            h2 = half * half
            s = h2 * _SINC_C5
            np.subtract(_SINC_C3, s, out=s)
            s *= h2
            np.subtract(_ONE, s, out=s)  # 1 - h2 (1/6 - h2 / 120)
            return s
        return np.sinc(half / np.pi)


def _zone_distance(sam_dist_m: np.ndarray, inner_m: np.ndarray, outer_m: np.ndarray) -> np.ndarray:
    """Distance from each UAV to its role's zone inner < D <= outer around the SAM (0 inside it)."""
    dist = sam_dist_m - outer_m
    np.maximum(dist, inner_m - sam_dist_m, out=dist)
    np.maximum(dist, _ZERO, out=dist)
    return dist


def _any_vehicle(flags: np.ndarray) -> np.ndarray:
    """(N,) any of the three columns of (N, 3) flags; two element-wise ORs (a reduction along an axis of
    length 3 runs N tiny inner loops, several times slower at large N)."""
    return flags[:, 0] | flags[:, 1] | flags[:, 2]


def _any_radar(inside: np.ndarray) -> np.ndarray:
    """(N, 3) any over the leading radar axis of (K, N, 3) flags: K - 1 element-wise ORs of whole (N, 3)
    slices, fast at any N (a reduction along the axis does the same but costs three ORs' time at N = 1)."""
    found = inside[0]
    for radar in inside[1:]:
        found = found | radar
    return found


def _and_not(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a & ~b`` for bool arrays in one call: True > False is the only pair that compares greater."""
    return np.greater(a, b)


def wrap_angle(angle: np.ndarray | float) -> np.ndarray | float:
    """Wrap an angle to [-pi, pi) (eq. 6 heading bounds)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def _max_radar_count(s: Scenario) -> int:
    if s.layout is not None:
        return max(1, len(s.layout.radars))
    assert s.random is not None
    return max(1, s.random.radar_count)


def role_index(role: Role | str) -> int:
    return ROLES.index(Role(role))
