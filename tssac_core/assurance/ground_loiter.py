"""A backup that stays bounded in wind: the ground-referenced loiter circle (issue 58, the monitor under real
dynamics, wind).

Pure numpy, vectorised over M vehicles, in the frames and units of :mod:`tssac_core.assurance.monitor` (x east,
y north, angles counter-clockwise from east; the wind is the air's velocity, east and north, m/s).

**Why a ground circle.** A constant heading rate flies a circle in the air mass; in a wind w the air mass moves and
the circle with it, W t metres after t seconds: no bound for ever. A loiter that holds a circle fixed to the ground
bends its path harder downwind than upwind, by a heading rate that follows the vehicle's position: a closed loop,
as ArduPlane's loiter holds its circle by varying bank.

**The circle's size.** In a steady wind w (|w| = W < V) a coordinated turn at heading rate psi' bends the ground path
g = V h(psi) + w (h the unit heading) with curvature

    kappa = V psi' (V + w . h) / |g|^3

so a ground circle of radius R needs psi' = |g|^3 / (R V (V + w . h)), the most downwind (|g| = V + W, w . h = W):
(V + W)^2 / (R V). Sized so that this takes a share ``authority`` of the turn-rate limit (the rest corrects errors),

    R = (V + W_max)^2 / (authority V omega_max)          (:func:`loiter_radius_m`)

(300 m/s in 10 m/s of wind at 5 deg/s, authority 0.95: 3.86 km; the calm air's maximum-rate circle: 3.44 km).

**The law** (:func:`loiter_turn_rate`). A vector field on the ground: at distance d from the centre c, the desired
track chi_d is the circle's tangent (the loiter's direction, ``sign`` +1 counter-clockwise) turned toward the circle
by atan((d - R) / L), L the law's lookahead; flown exactly it brings d to R (d' = -|g| sin atan((d - R) / L)). The
track rate commanded is the field's own rate along the path plus a gain on the track's error,

    chi'_cmd = theta' + sign (r . g) / (d L (1 + ((d - R) / L)^2)) + k (chi_d - chi),    theta' = (r x g) / d^2

(r = p - c), and the heading rate that gives it, by the curvature above (chi' = kappa |g|),
psi'_cmd = chi'_cmd |g|^2 / (V (V + w . h)), clipped to the turn-rate limit. Its inputs are what a companion knows:
position, ground velocity and the wind (the heading follows: h = (g - w) / V).

**Its bound.** A backup in wind flies straight for its lead, then its *turn-in*: a maximum-rate turn the loiter's way
for long enough that the airframe turns at its limit whatever it did before (its delay and four time constants), and
then the loiter, its centre at R from the vehicle on the turn's side of its ground track (:func:`loiter_centre`).
Entered from a turn at the limit its way, tighter than the circle needs anywhere, the loiter starts inside its circle
and stays within R + E of the centre for ever, E the *excursion* measured against the airframe (JSBSim) at the
declared maximum wind from every direction and the speeds of the envelope, kept as data beside the airframe's
response; entered from a turn the other way it would first swing out by hundreds of metres (a reversal at full bank),
which is what the turn-in spends its few seconds to avoid. On the airframe's lag model (:func:`fly_loiter_on_model`)
the loop settles on its circle within a lap and its excursion does not grow from one lap to the next.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from tssac_core.assurance.lagged_backups import (
    SETTLE_TIME_CONSTANTS,
    AirframeLag,
    LagState,
    Rollout,
    lag_gains,
    lagged_rollout,
    lead_ends,
    switched_lag_step,
)
from tssac_core.assurance.monitor import N_TURNS, EstimateError, Hazards, Limits, circle_clearance, point_clearance


@dataclass(frozen=True)
class LoiterLaw:
    """The ground loiter's gains (module docstring)."""

    authority: float = 0.95
    """The share of the turn-rate limit the steady circle needs at its most (the rest corrects errors), in (0, 1]."""
    lookahead_share: float = 0.5
    """The vector field's lookahead L as a share of the radius."""
    track_gain_1_s: float = 0.3
    """The gain on the track's error (1/s): below about 1 / (2 tau) of the airframe's lag, or the loop rings."""

    def __post_init__(self) -> None:
        if not (0.0 < self.authority <= 1.0 and self.lookahead_share > 0.0 and self.track_gain_1_s > 0.0):
            raise ValueError(f"a loiter law needs 0 < authority <= 1 and a positive lookahead and gain: {self}")


def loiter_radius_m(
    speed_m_s: np.ndarray, wind_max_m_s: float, turn_rate_max_rad_s: np.ndarray, authority: float
) -> np.ndarray:
    """R = (V + W_max)^2 / (authority V omega_max) (module docstring), (M,)."""
    v = np.asarray(speed_m_s, dtype=np.float64)
    return (v + wind_max_m_s) ** 2 / (authority * v * np.asarray(turn_rate_max_rad_s, dtype=np.float64))


def loiter_centre(
    x: np.ndarray, y: np.ndarray, gx: np.ndarray, gy: np.ndarray, sign: np.ndarray | float, radius: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The centre of the circle of ``radius`` the vehicle at (x, y), moving over the ground at (gx, gy), starts on,
    tangent to its ground track, on the side it turns to (``sign`` +1 left: counter-clockwise)."""
    speed = np.hypot(gx, gy)
    return x - sign * radius * gy / speed, y + sign * radius * gx / speed


def loiter_turn_rate(
    x: np.ndarray,
    y: np.ndarray,
    gx: np.ndarray,
    gy: np.ndarray,
    wind_x: np.ndarray | float,
    wind_y: np.ndarray | float,
    cx: np.ndarray,
    cy: np.ndarray,
    radius: np.ndarray,
    sign: np.ndarray | float,
    turn_rate_max_rad_s: np.ndarray,
    law: LoiterLaw,
) -> np.ndarray:
    """The heading-rate command (rad/s, counter-clockwise positive) that holds the ground circle (module
    docstring), (M,)."""
    rx, ry = x - cx, y - cy
    d = np.maximum(np.hypot(rx, ry), 1e-6)
    ground = np.maximum(np.hypot(gx, gy), 1e-6)
    lookahead = law.lookahead_share * radius
    q = (d - radius) / lookahead
    tangent = np.arctan2(sign * rx, -sign * ry)  # the radial direction turned by sign * 90 deg
    desired = tangent + sign * np.arctan(q)
    track = np.arctan2(gy, gx)
    error = np.mod(desired - track + np.pi, 2.0 * np.pi) - np.pi
    field_rate = (rx * gy - ry * gx) / d**2 + sign * (rx * gx + ry * gy) / (d * lookahead * (1.0 + q * q))
    track_rate = field_rate + law.track_gain_1_s * error
    ax, ay = gx - wind_x, gy - wind_y  # the air velocity V h
    airspeed = np.maximum(np.hypot(ax, ay), 1e-6)
    along = (ax * gx + ay * gy) / airspeed  # V + w . h = g . h
    heading_rate = track_rate * ground**2 / (airspeed * np.maximum(along, 1e-6))
    limit = np.asarray(turn_rate_max_rad_s, dtype=np.float64)
    return np.clip(heading_rate, -limit, limit)


def loiter_action(
    x: np.ndarray,
    y: np.ndarray,
    gx: np.ndarray,
    gy: np.ndarray,
    wind_x: np.ndarray | float,
    wind_y: np.ndarray | float,
    circle: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | float],
    turn_rate_max_rad_s: np.ndarray,
    law: LoiterLaw,
) -> np.ndarray:
    """The normalised action [omega, u] (M, 2) that flies the loiter ``circle`` (centre x, centre y, radius, sign):
    :func:`loiter_turn_rate` over the limit, the speed held."""
    cx, cy, radius, sign = circle
    limit = np.asarray(turn_rate_max_rad_s, dtype=np.float64)
    rate = loiter_turn_rate(x, y, gx, gy, wind_x, wind_y, cx, cy, radius, sign, limit, law)
    return np.stack([rate / limit, np.zeros(len(rate))], axis=-1)


@dataclass(frozen=True)
class LoiterFlight:
    """A loiter flown on the model: positions after steps 1..S, (M, S) each."""

    xs: np.ndarray
    ys: np.ndarray
    rates: np.ndarray
    """(M, S) the heading rate flown at the end of each step."""


def fly_loiter_on_model(
    x: np.ndarray,
    y: np.ndarray,
    v: np.ndarray,
    psi: np.ndarray,
    lag_state: LagState,
    wind: tuple[np.ndarray | float, np.ndarray | float],
    centre: tuple[np.ndarray, np.ndarray],
    radius: np.ndarray,
    sign: np.ndarray | float,
    airframe: AirframeLag,
    turn_rate_max_rad_s: np.ndarray,
    law: LoiterLaw,
    dt_s: float,
    steps: int,
) -> LoiterFlight:
    """Fly the loiter ``steps`` world steps at constant airspeed under the airframe's lag model
    (:mod:`tssac_core.assurance.lagged_backups`) in a steady wind: each step the law's command from the state, followed
    after the delay through the lag; the air-mass arc (eq. 5 at the step's mean rate) plus the wind's w dt."""
    m = len(x)
    wx, wy = (np.broadcast_to(np.asarray(c, dtype=np.float64), (m,)) for c in wind)
    cx, cy = centre
    width = lag_state.pending_rad_s.shape[1]
    queue = np.concatenate([lag_state.pending_rad_s, np.zeros((m, steps))], axis=1)
    start = width - airframe.delay_steps
    if np.any(start < 0):
        raise ValueError(f"LagState: {width} pending commands, but a delay of {airframe.delay_steps.max()} steps")
    gains_in, gains_out = lag_gains(airframe.tau_s, dt_s), lag_gains(airframe.rollout_tau_s, dt_s)
    px, py, ph = (np.asarray(a, dtype=np.float64).copy() for a in (x, y, psi))
    speed = np.asarray(v, dtype=np.float64)
    omega = lag_state.omega_rad_s.astype(np.float64)
    rows = np.arange(m)
    out = np.empty((3, m, steps))
    for k in range(steps):
        gx, gy = speed * np.cos(ph) + wx, speed * np.sin(ph) + wy
        queue[:, width + k] = loiter_turn_rate(px, py, gx, gy, wx, wy, cx, cy, radius, sign, turn_rate_max_rad_s, law)
        rate, omega = switched_lag_step(omega, queue[rows, start + k], gains_in, gains_out)
        half = 0.5 * rate * dt_s
        chord = speed * dt_s * np.sinc(half / np.pi)
        px = px + chord * np.cos(ph + half) + wx * dt_s
        py = py + chord * np.sin(ph + half) + wy * dt_s
        ph = ph + rate * dt_s
        out[:, :, k] = px, py, omega
    return LoiterFlight(out[0], out[1], out[2])


# ------------------------------------------------------------------------------------------ the monitor's backups


@dataclass(frozen=True)
class WindLoiter:
    """What the monitor's backups need in wind, (M,) arrays: the steady wind the vehicle flies in (east, north, m/s;
    the world's own, or the vehicle's WIND report), the largest the scenario promises (the circles are sized for it),
    the loiter law and how far beyond its radius the airframe flies it (the response file's fitted excursion at each
    vehicle's speed)."""

    east_m_s: np.ndarray
    north_m_s: np.ndarray
    max_m_s: float
    law: LoiterLaw
    excursion_m: np.ndarray
    heading_residual_rad: np.ndarray
    """How far the airframe's heading may lie from the model's where the loiter starts (0 where the model is the
    truth, as in the batched world's varied airframes)."""
    residual_m: np.ndarray
    """How far the airframe's path may lie from the model's over a backup's lead and turn-in (0 where the model is the
    truth): taken off the backups' clearance in wind."""
    turn_in_s: float = 0.0
    """How long a backup's maximum-rate turn flies between its lead and its loiter (module docstring; 0: the loiter
    starts where the lead ends)."""

    def select(self, rows: np.ndarray) -> WindLoiter:
        return WindLoiter(
            self.east_m_s[rows],
            self.north_m_s[rows],
            self.max_m_s,
            self.law,
            self.excursion_m[rows],
            self.heading_residual_rad[rows],
            self.residual_m[rows],
            self.turn_in_s,
        )

    def turn_in_steps(self, dt_s: float) -> int:
        """The turn-in in world steps (rounded up)."""
        return turn_in_steps(self.turn_in_s, dt_s)

    def drift(self, steps: int, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(M, steps) how far the air mass carries a vehicle after steps 1..``steps``: w k dt."""
        t = dt_s * np.arange(1, steps + 1)[None, :]
        return self.east_m_s[:, None] * t, self.north_m_s[:, None] * t

    def radius_m(self, speed_m_s: np.ndarray, turn_rate_max_rad_s: np.ndarray) -> np.ndarray:
        """The loiter circle's radius at each airspeed (:func:`loiter_radius_m`)."""
        return loiter_radius_m(speed_m_s, self.max_m_s, turn_rate_max_rad_s, self.law.authority)


def carried_rollout(
    x: np.ndarray,
    y: np.ndarray,
    v: np.ndarray,
    phi: np.ndarray,
    lag_state: LagState,
    turn_commands_rad_s: np.ndarray,
    airframe: AirframeLag,
    lim: Limits,
    dt_s: float,
    wind_m_s: tuple[np.ndarray | float, np.ndarray | float],
) -> Rollout:
    """:func:`lagged_rollout` of the (M, S) heading-rate commands at constant speed (acceleration 0) through the air,
    its positions carried over the ground by the wind (east, north; per state or one for all): where a backup's lead
    and turn-in are predicted to fly in wind."""
    path = lagged_rollout(
        x, y, v, phi, lag_state, turn_commands_rad_s, np.zeros_like(turn_commands_rad_s), airframe, lim, dt_s
    )
    t = dt_s * np.arange(1, turn_commands_rad_s.shape[1] + 1)[None, :]
    east, north = (np.asarray(w, dtype=np.float64).reshape(-1, 1) for w in wind_m_s)
    return dataclasses.replace(path, xs=path.xs + east * t, ys=path.ys + north * t)


def loiter_keep_out(
    x: np.ndarray,
    y: np.ndarray,
    v: np.ndarray,
    phi: np.ndarray,
    sign: np.ndarray | float,
    wind: WindLoiter,
    turn_rate_max_rad_s: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The disk a loiter started from each state (airspeed ``v``, heading ``phi``) never leaves: centre (M,) x, y at
    R from the vehicle on the turn's side of its ground track, radius R + the excursion (module docstring), + R times
    the largest error of the ground track where it starts: a heading off by d turns the ground velocity v h + w by at
    most d v / (v - W_max), and the centre, at R normal to it, moves by R times that."""
    gx, gy = v * np.cos(phi) + wind.east_m_s, v * np.sin(phi) + wind.north_m_s
    radius = wind.radius_m(v, turn_rate_max_rad_s)
    cx, cy = loiter_centre(x, y, gx, gy, sign, radius)
    track_error = wind.heading_residual_rad * v / (v - wind.max_m_s)
    return cx, cy, radius + wind.excursion_m + radius * track_error


def loiter_backup_clearance(
    x: np.ndarray,
    y: np.ndarray,
    v: np.ndarray,
    phi: np.ndarray,
    lag_state: LagState,
    hz: Hazards,
    airframe: AirframeLag,
    lim: Limits,
    dt_s: float,
    leads: np.ndarray,
    wind: WindLoiter,
) -> np.ndarray:
    """Clearance of every backup in wind flown for ever from each state, less the airframe's residual over a lead and
    turn-in (:attr:`WindLoiter.residual_m`), (M, L * 2)
    (candidate lead * 2 + loiter; 0 left, 1 right, as the monitor's first two ``TURNS``).

    A backup flies straight (heading-rate command 0, speed held) for its lead of ``leads`` world steps under the lag
    model, carried by the wind, then its maximum-rate turn for the turn-in (:attr:`WindLoiter.turn_in_s`), then the
    ground loiter for ever: the lead's and the turn-in's samples (less half a step's ground distance,
    (v_max + W_max) dt / 2, each) and the loiter's disk from the turn-in's end (:func:`loiter_keep_out`)."""
    m, n_leads = len(x), len(leads)
    half_step = (lim.speed_max_m_s + wind.max_m_s) * dt_s / 2
    carried = (wind.east_m_s, wind.north_m_s)
    ends = lead_ends(x, y, v, phi, lag_state, hz, airframe, lim, dt_s, leads, half_step, carried)
    rows, both = np.repeat(np.arange(m), n_leads * 2), np.arange(m * n_leads).repeat(2)
    ex, ey, ev, ep = (a.reshape(-1)[both] for a in (ends.xs, ends.ys, ends.speeds, ends.headings))
    lag = ends.lag.select(both)
    sign = np.tile([1.0, -1.0], m * n_leads)
    r_wind, r_hz, r_lim = wind.select(rows), hz.select(rows), lim.select(rows)
    least = ends.least_m.reshape(-1)[both]
    steps = wind.turn_in_steps(dt_s)
    if steps:
        command = np.repeat((sign * r_lim.turn_rate_max_rad_s)[:, None], steps, axis=1)
        drift = (r_wind.east_m_s, r_wind.north_m_s)
        path = carried_rollout(ex, ey, ev, ep, lag, command, airframe.select(rows), r_lim, dt_s, drift)
        least = np.minimum(least, point_clearance(path.xs, path.ys, r_hz).min(axis=1) - half_step[rows])
        ex, ey, ev, ep = path.xs[:, -1], path.ys[:, -1], path.speeds[:, -1], path.headings[:, -1]
    cx, cy, radius = loiter_keep_out(ex, ey, ev, ep, sign, r_wind, r_lim.turn_rate_max_rad_s)
    out = np.minimum(least, circle_clearance(cx, cy, radius, r_hz)).reshape(m, n_leads * 2)
    return out - wind.residual_m[:, None]


def centre_per_heading_m(
    speed_min_m_s: np.ndarray,
    speed_max_m_s: np.ndarray,
    wind_max_m_s: float,
    turn_rate_max_rad_s: np.ndarray,
    law: LoiterLaw,
) -> np.ndarray:
    """(M,) how far the loiter's centre moves per radian of heading error at the turn-in's end, at the worst airspeed
    of the envelope: max over V of R(V) V / (V - W) = (V + W)^2 / (authority omega_max (V - W)), a function with one
    minimum (at V = 3 W), so its largest value on [v_min, v_max] is at one of the two ends."""
    w = np.asarray(turn_rate_max_rad_s, dtype=np.float64)

    def at(v: np.ndarray) -> np.ndarray:
        v = np.asarray(v, dtype=np.float64)
        return (v + wind_max_m_s) ** 2 / (law.authority * w * (v - wind_max_m_s))

    return np.maximum(at(speed_min_m_s), at(speed_max_m_s))


def loiter_backup_error_m(
    err: EstimateError, lim: Limits, dt_s: float, leads: np.ndarray, wind: WindLoiter
) -> np.ndarray:
    """How much of each backup's clearance in wind the state's error can take away, (M, L * N_TURNS), in metres (as
    :func:`~tssac_core.assurance.monitor.backup_error_m` for the calm air's backups).

    Flown from a state off by (d_p, d_phi, d_v), the lead and the turn-in (open loop, time T in all) move by at most
    d_p + v_max T d_phi + T d_v; the loiter's centre, at R from the turn-in's end normal to its ground track, by that
    plus R(V) d_track + dR/dV d_v,
    where a heading error turns the ground track at airspeed V by at most d_phi V / (V - W_max) (the air velocity
    turned by d_phi moves the ground velocity by V d_phi, and |g| >= V - W_max), so the centre by
    d_phi R(V) V / (V - W_max) = d_phi (V + W)^2 / (authority omega_max (V - W)) (:func:`centre_per_heading_m`), and
    dR/dV = (V + W)(V - W) / (authority omega_max V^2) <= 1 / (authority omega_max); its radius by dR/dV d_v. The
    loiter is a closed loop on the flier's estimate of its position, which may be off by d_p again: the circle it
    holds moves by that much too (2 d_p in all)."""
    t = (leads.astype(np.float64)[None, :] + wind.turn_in_steps(dt_s)) * dt_s
    w, vmax = lim.turn_rate_max_rad_s[:, None], lim.speed_max_m_s[:, None]
    centre = centre_per_heading_m(lim.speed_min_m_s, lim.speed_max_m_s, wind.max_m_s, lim.turn_rate_max_rad_s, wind.law)
    lever = vmax * t + centre[:, None]
    secs = t + 2.0 / (wind.law.authority * w)
    one = 2.0 * err.position_m[:, None] + err.heading_rad[:, None] * lever + err.speed_m_s[:, None] * secs
    return np.repeat(one[:, :, None], N_TURNS, axis=2).reshape(len(err.position_m), len(leads) * N_TURNS)


@dataclass(frozen=True)
class LoiterBound:
    """The ground loiter's figures for a fleet: the largest wind the scenario promises (the circles are sized for it),
    the law, and how far beyond its radius an airframe flies it, per speed (between two tabled speeds the worse
    neighbour's; the speeds are the airframe's envelope)."""

    max_m_s: float
    law: LoiterLaw
    speeds_m_s: tuple[float, ...]
    excursion_m: tuple[float, ...]
    heading_residual_rad: tuple[float, ...] = ()
    """Per speed, how far the airframe's heading may lie from the model's (:class:`WindLoiter`); empty: 0."""
    residual_m: tuple[float, ...] = ()
    """Per speed, how far the airframe's path may lie from the model's over a lead and turn-in
    (:class:`WindLoiter`); empty: 0."""
    turn_in_s: float = 0.0
    """The turn-in the excursion was measured after (:attr:`WindLoiter.turn_in_s`)."""

    def __post_init__(self) -> None:
        n = len(self.speeds_m_s)
        optional = (self.heading_residual_rad, self.residual_m)
        if not n or len(self.excursion_m) != n or any(len(t) not in (0, n) for t in optional):
            raise ValueError(f"a loiter bound needs one excursion (and residual) per speed: {self}")
        if not (math.isfinite(self.turn_in_s) and self.turn_in_s >= 0.0):
            raise ValueError(f"a loiter bound's turn-in must be a time >= 0: {self.turn_in_s}")

    def _worse_neighbour(self, values: tuple[float, ...], speed_m_s: np.ndarray) -> np.ndarray:
        """(M,) a table's value at each speed: the worse of its two tabled neighbours (the nearest end outside)."""
        table, column = np.asarray(self.speeds_m_s), np.asarray(values)
        hi = np.clip(np.searchsorted(table, speed_m_s), 0, len(table) - 1)
        lo = np.clip(hi - 1, 0, len(table) - 1)
        exact = np.isclose(table[hi], speed_m_s)
        return np.where(exact, column[hi], np.maximum(column[lo], column[hi]))

    def radius_m(self, speed_m_s: np.ndarray, turn_rate_max_rad_s: np.ndarray) -> np.ndarray:
        """The loiter circle's radius at each airspeed, sized for the promised wind (:func:`loiter_radius_m`)."""
        return loiter_radius_m(speed_m_s, self.max_m_s, turn_rate_max_rad_s, self.law.authority)

    def turn_in_steps(self, dt_s: float) -> int:
        """The turn-in in world steps (rounded up)."""
        return turn_in_steps(self.turn_in_s, dt_s)

    def excursion_at(self, speed_m_s: np.ndarray) -> np.ndarray:
        """(M,) the excursion at each speed (the worse neighbour's between two tabled speeds)."""
        return self._worse_neighbour(self.excursion_m, speed_m_s)

    def wind(self, east_m_s: np.ndarray, north_m_s: np.ndarray, speed_m_s: np.ndarray) -> WindLoiter:
        """The monitor's :class:`WindLoiter` for vehicles in these winds at these speeds."""
        speeds = np.asarray(speed_m_s, dtype=np.float64)
        zeros = (0.0,) * len(self.speeds_m_s)
        return WindLoiter(
            np.asarray(east_m_s),
            np.asarray(north_m_s),
            self.max_m_s,
            self.law,
            self.excursion_at(speeds),
            self._worse_neighbour(self.heading_residual_rad or zeros, speeds),
            self._worse_neighbour(self.residual_m or zeros, speeds),
            self.turn_in_s,
        )


def turn_in_steps(turn_in_s: float, dt_s: float) -> int:
    """A turn-in of ``turn_in_s`` in world steps of ``dt_s``, rounded up (a float's last digit aside)."""
    return math.ceil(turn_in_s / dt_s - 1e-9)


def settled_turn_in_s(delay_s: float, tau_s: float) -> float:
    """The turn-in an airframe needs to settle into its maximum-rate turn from anything (a reversal at full bank the
    slowest): its delay and ``SETTLE_TIME_CONSTANTS`` of its longest time constant, up to the next whole second."""
    return float(math.ceil(delay_s + SETTLE_TIME_CONSTANTS * tau_s - 1e-9))


MODEL_LAPS = 1.25
"""How long a model run of :func:`model_excursion_m` flies, in laps of its circle into the wind: the entry's
excursion comes within the first quarter."""


def model_excursion_m(
    lags: AirframeLag,
    speeds_m_s: tuple[float, ...],
    wind_max_m_s: float,
    law: LoiterLaw,
    turn_rate_max_rad_s: float,
    dt_s: float,
    directions: int = 8,
    turn_in_s: float = 0.0,
) -> tuple[float, ...]:
    """Per speed, the largest distance beyond the radius at which the loiter is flown on the lag model by any of the
    K airframes ``lags`` ((K,) arrays), entered from a maximum-rate turn against it, straight flight and a maximum-rate
    turn its way, each followed by the turn-in of ``turn_in_s`` (a maximum-rate turn its way), in calm air and in
    ``wind_max_m_s`` from ``directions`` directions, both ways round (the model's part of the fit, for airframes drawn
    from ranges: flown at the ranges' corners)."""
    k = len(lags.tau_s)
    winds = [(0.0, 0.0)] + [
        (wind_max_m_s * math.cos(a), wind_max_m_s * math.sin(a))
        for a in np.linspace(0.0, 2.0 * math.pi, directions, endpoint=False)
    ]
    grid = np.array(
        [
            (s, wx, wy, e, d, a)
            for s in speeds_m_s
            for wx, wy in winds
            for e in (-1.0, 0.0, 1.0)
            for d in (1.0, -1.0)
            for a in range(k)
        ]  # fmt: skip
    )
    v, wx, wy, entry, sign = (grid[:, i] for i in range(5))
    air = lags.select(grid[:, 5].astype(np.int64))
    m = len(grid)
    limit = np.full(m, turn_rate_max_rad_s)
    x, y, heading = np.zeros(m), np.zeros(m), np.zeros(m)
    lag = LagState.steady(entry * sign * turn_rate_max_rad_s, int(air.delay_steps.max(initial=0)))
    steps_in = turn_in_steps(turn_in_s, dt_s)
    if steps_in:
        held = Limits(v, v, limit, np.zeros(m))
        command = np.repeat((sign * limit)[:, None], steps_in, axis=1)
        turn = carried_rollout(x, y, v, heading, lag, command, air, held, dt_s, (wx, wy))
        x, y, heading, lag = turn.xs[:, -1], turn.ys[:, -1], turn.headings[:, -1], turn.lag_after(steps_in)
    radius = loiter_radius_m(v, wind_max_m_s, limit, law.authority)
    cx, cy = loiter_centre(x, y, v * np.cos(heading) + wx, v * np.sin(heading) + wy, sign, radius)
    steps = math.ceil(MODEL_LAPS * 2.0 * math.pi * radius.max() / (min(speeds_m_s) - wind_max_m_s) / dt_s)
    flight = fly_loiter_on_model(x, y, v, heading, lag, (wx, wy), (cx, cy), radius, sign, air, limit, law, dt_s, steps)
    beyond = (np.hypot(flight.xs - cx[:, None], flight.ys - cy[:, None]) - radius[:, None]).max(axis=1)
    return tuple(float(beyond[v == s].max()) for s in speeds_m_s)
