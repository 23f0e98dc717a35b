"""Runtime assurance (Simplex): a monitor that lets a UAV fly its policy's action only if it can still be saved.

Pure functions, numpy only (the MAVLink companion imports this module and must not import torch or
gymnasium), vectorised over M vehicles: the batched world's evaluation (M = 3 N) and a companion (M = 1)
call the same :func:`decide` and take the same decision for the same state. The argument, with its
numbers, is in ``docs/runtime_assurance.md``; in short:

* **Backups.** Four fixed manoeuvres, each one constant command held for ever: a maximum-rate turn
  (left or right) at constant speed (u = 0), a circle of radius r = v / omega_max; or a maximum-rate turn
  while braking at the maximum rate (u = -1), a spiral that ends, once v reaches v_min (at most
  (v_max - v_min) / a_max = 15 s), on the circle of radius v_min / omega_max (1.72 km instead of 3.44 km
  at top speed). A fixed wing holds either for ever.
* **Clearance of a backup** from a state: the smallest distance from its path to the edge of a radar's
  disk or of the area. The final circle is exact (its centre's distance to each radar centre minus the
  radar's radius and r; to each edge minus r); the braking spiral's points are the world's own eq. 5
  samples at dt, less v_max dt / 2 (no point of an arc between two samples is farther than that from one
  of them). A state from which some backup has clearance >= margin is *recoverable*.
* **Decision** (at each of the policy's decisions, every ``steps`` world steps): predict the path from
  the estimate, first through the commands already sent but not yet flown (``pending``: the link's
  latency), then ``steps`` steps of the proposed action (eq. 5-6 integrated as the world does). The
  action passes if (a) every predicted point is at least margin + v_max dt / 2 from every disk and edge,
  and (b) some backup from the predicted end state has clearance >= margin. Passed: fly it and remember
  that backup. Failed: fly the backup remembered at the last decision, which starts exactly where the
  vehicle is when the command takes effect (it was planned from that decision's predicted end state,
  or the vehicle is already flying it): by induction the UAV never comes nearer than margin to a disk
  or an edge.
* **Adjusted actions** (``ShieldConfig.adjust``, off by default). A proposal that fails while the policy flies is
  first replaced by the passing action nearest it among :func:`adjusted_candidates`; the backup flies only when none
  passes. Each candidate passes the same (a) and (b), so the induction is unchanged.
* **Hysteresis.** Once engaged, control goes back to the policy only after its action has passed with
  margin + ``release_margin_m`` for ``release_decisions`` consecutive decisions, so each engagement lasts
  at least that many decisions and the switch count is bounded by the decisions / release_decisions.
* **No recoverable start.** If the first decision finds no passing action and no backup clear of the
  margin, the vehicle is *unprotected*: it flies the backup with the largest clearance (the best it
  can do) and is counted; it becomes protected at the first action that passes.

Frames and units as in :mod:`tssac_core.sim.world`: x east, y north from the area's south-west corner (m),
heading phi counter-clockwise from east (rad), speed v (m/s); actions [omega, u] in [-1, 1] scaled by
the vehicle's limits (eq. 8).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

TURNS = np.array([[1.0, 0.0], [-1.0, 0.0], [1.0, -1.0], [-1.0, -1.0]])
"""The backups' final commands [omega, u]: a left / right maximum-rate turn at constant speed, then the same
while braking at the maximum rate (omega > 0 turns left, counter-clockwise)."""
N_TURNS = len(TURNS)


@dataclass(frozen=True)
class ShieldConfig:
    """The monitor's margins and hysteresis."""

    margin_m: float = 100.0
    """Clearance every accepted path and backup keeps from a radar's disk and from the area's edges (the bound
    on the estimate's error comes on top of it, per backup: :class:`EstimateError`)."""
    release_margin_m: float = 1000.0
    """Extra clearance the policy's action needs, while the backup flies, to get control back."""
    release_decisions: int = 3
    """Consecutive decisions that must pass with the extra clearance before control goes back."""
    sigma_k: float = 3.0
    """Companion: the margin grows by sigma_k times the position estimate's largest standard deviation."""
    straight_leads_s: tuple[float, ...] = (0.0, 4.0, 8.0, 16.0, 32.0)
    """Each backup first flies straight for one of these times (at constant speed, or braking for the braking
    turns), then turns for ever: 0 is the plain loiter circle; the longer ones carry a UAV through a gap
    between two radars that is too narrow for a circle, or past a radar it is flying along."""
    braking_backups: bool = True
    """Also the backups that brake to v_min while they turn (their 1.72 km final circle fits where the
    3.44 km one at top speed does not; False: constant-speed turns only, cheaper to check)."""
    timing_slack_s: float = 0.5
    """Companion off lockstep: the margin grows by v_max times this (a companion that falls behind the
    vehicle's clock on a loaded machine: the vehicle flies the previous command meanwhile)."""
    handover_ticks: int = 1
    """Companion over a lossy link or off lockstep: setpoints in a row that may be lost or late when the command
    changes (the vehicle flies the previous one that long); the error bound covers this many (see
    :func:`handover_error`)."""
    adjust: bool = False
    """When the proposed action fails and the backup is not flying: first the passing action nearest the proposal among
    :func:`adjusted_candidates` flies; the backup takes over only when none passes (False: the backup at once). A
    flying backup still goes back to the proposal alone, by the release rule."""
    route_edge_margin_m: float = 0.0
    """Asked of the pilot, not checked by the monitor: the route field a policy observes treats this band inside the
    area's edge as a hazard, so that the way it is shown round the radars leaves the backups their room at the
    geofence (``tssac_core.sim.pilot_view``; 0: the route as trained)."""
    radar_view_margin_m: float = 0.0
    """Asked of the pilot, not checked by the monitor: the pilot is shown every radar this much larger than it is, so
    that it keeps the backups' room from the radars itself (``tssac_core.sim.pilot_view``; 0: as they are)."""

    def __post_init__(self) -> None:
        for name in (
            "margin_m",
            "release_margin_m",
            "sigma_k",
            "timing_slack_s",
            "route_edge_margin_m",
            "radar_view_margin_m",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"ShieldConfig.{name} must be a finite number >= 0, got {value}")
        if not self.straight_leads_s or any(not (math.isfinite(t) and t >= 0) for t in self.straight_leads_s):
            raise ValueError(f"ShieldConfig.straight_leads_s must be times >= 0, got {self.straight_leads_s}")
        if self.release_decisions < 1:
            raise ValueError(f"ShieldConfig.release_decisions must be >= 1, got {self.release_decisions}")
        if self.handover_ticks < 0:
            raise ValueError(f"ShieldConfig.handover_ticks must be >= 0, got {self.handover_ticks}")

    def with_leads(self, leads_s: tuple[float, ...]) -> ShieldConfig:
        """This configuration offering ``leads_s`` as well (an airframe's held leads in calm air)."""
        return dataclasses.replace(self, straight_leads_s=tuple(sorted({*self.straight_leads_s, *leads_s})))


@dataclass(frozen=True)
class Limits:
    """Each vehicle's limits (eq. 6, 8), arrays of shape (M,)."""

    speed_min_m_s: np.ndarray
    speed_max_m_s: np.ndarray
    turn_rate_max_rad_s: np.ndarray
    accel_max_m_s2: np.ndarray

    def select(self, idx: np.ndarray) -> Limits:
        return Limits(
            self.speed_min_m_s[idx], self.speed_max_m_s[idx], self.turn_rate_max_rad_s[idx], self.accel_max_m_s2[idx]
        )


@dataclass(frozen=True)
class Hazards:
    """What the vehicles must keep out of: radar disks (unused slots: radius 0) and the square area."""

    centres_m: np.ndarray
    """(M, K, 2) radar centres, x over y."""
    radii_m: np.ndarray
    """(M, K) radar radii (0: an unused slot, never a hazard)."""
    area_m: float
    """The area is [0, area_m]^2 (eq. 6 position bounds)."""

    def select(self, idx: np.ndarray) -> Hazards:
        return Hazards(self.centres_m[idx], self.radii_m[idx], self.area_m)


@dataclass(frozen=True)
class Memory:
    """What the monitor remembers per vehicle between decisions, (M,) arrays."""

    engaged: np.ndarray
    """The backup is flying."""
    protected: np.ndarray
    """A backup clear of the margin is known from the state the next command starts from."""
    backup: np.ndarray
    """Which backup (candidate index: lead * N_TURNS + turn) flies when the monitor engages (or flies now)."""
    lead_left: np.ndarray
    """World steps of the backup's straight lead still to fly."""
    passes: np.ndarray
    """While engaged: consecutive decisions whose proposed action passed with the release margin."""
    held_course: np.ndarray
    """The course the backup's lead holds after its open part, as the check predicted it (rad; NaN: a lead flown open
    loop to its end, :func:`tssac_core.assurance.lagged_backups.held_rollout`)."""

    @staticmethod
    def initial(m: int) -> Memory:
        """Before the first decision: nothing known, nothing engaged."""
        z = np.zeros(m, np.int64)
        return Memory(np.zeros(m, bool), np.zeros(m, bool), z, z.copy(), z.copy(), np.full(m, np.nan))

    def select(self, idx: np.ndarray) -> Memory:
        return Memory(
            self.engaged[idx],
            self.protected[idx],
            self.backup[idx],
            self.lead_left[idx],
            self.passes[idx],
            self.held_course[idx],
        )

    def merged(self, idx: np.ndarray, part: Memory) -> Memory:
        """A copy with vehicles ``idx`` replaced by ``part``."""
        out = Memory(
            self.engaged.copy(),
            self.protected.copy(),
            self.backup.copy(),
            self.lead_left.copy(),
            self.passes.copy(),
            self.held_course.copy(),
        )
        out.engaged[idx], out.protected[idx], out.backup[idx] = part.engaged, part.protected, part.backup
        out.lead_left[idx], out.passes[idx], out.held_course[idx] = part.lead_left, part.passes, part.held_course
        return out


@dataclass(frozen=True)
class EstimateError:
    """Bounds on how far the state the monitor decides from may be off the vehicle's true state, (M,) arrays.

    The batched world decides from the true state (all zero). A companion decides from its Kalman filter's
    estimate: ``sigma_k`` standard deviations of position (the covariance's major axis), heading and speed
    (:func:`companion_error`), plus what a setpoint lost or late at a hand-over does (:func:`handover_error`).
    :func:`backup_error_m` turns them into metres of clearance, per backup.
    """

    position_m: np.ndarray
    heading_rad: np.ndarray
    speed_m_s: np.ndarray

    @staticmethod
    def zero(m: int) -> EstimateError:
        return EstimateError(np.zeros(m), np.zeros(m), np.zeros(m))

    def select(self, rows: np.ndarray) -> EstimateError:
        return EstimateError(self.position_m[rows], self.heading_rad[rows], self.speed_m_s[rows])

    def __add__(self, other: EstimateError) -> EstimateError:
        return EstimateError(
            self.position_m + other.position_m, self.heading_rad + other.heading_rad, self.speed_m_s + other.speed_m_s
        )

    def after(self, seconds: float, lim: Limits) -> EstimateError:
        """The same bounds after flying ``seconds`` of known commands from the estimate: a heading error turns the
        path (at most v_max d_phi metres per second), a speed error stretches it (d_v per second); the heading and
        speed errors stay (the commands are rates and accelerations, the same on both paths)."""
        drift = (self.heading_rad * lim.speed_max_m_s + self.speed_m_s) * seconds
        return EstimateError(self.position_m + drift, self.heading_rad, self.speed_m_s)


@dataclass(frozen=True)
class Decision:
    """What one decision gives, (M,) arrays unless said."""

    action: np.ndarray
    """(M, 2) the action to fly for the next interval: the proposed one or a backup's."""
    memory: Memory
    engaged: np.ndarray
    """The backup flies this interval."""
    adjusted: np.ndarray
    """The monitor's nearest passing candidate flies this interval, not the proposal (:attr:`ShieldConfig.adjust`)."""
    engaged_now: np.ndarray
    """The backup took over at this decision (an intervention)."""
    released_now: np.ndarray
    """Control went back to the policy at this decision."""
    unprotected: np.ndarray
    """No passing action and no clear backup: flying the best backup without a guarantee."""
    clearance_m: np.ndarray
    """The proposed action's clearance (the adjusted action's when one flies): min((a) its path's, (b) its best
    backup's), in metres."""
    straight_steps: np.ndarray
    """World steps of the interval to fly ``action`` before a flying backup's lead ends (the interval's ``steps``
    when nothing changes in it): from then on the backup flies ``turn``."""
    turn: np.ndarray
    """(M, 2) the turn of the backup, flown after its lead."""

    def action_at(self, step: int) -> np.ndarray:
        """(M, 2) the command to fly ``step`` world steps after the decision (0: at it)."""
        return np.where((step < self.straight_steps)[:, None], self.action, self.turn)


# ------------------------------------------------------------------------------- kinematics


def _sinc(half: np.ndarray) -> np.ndarray:
    return np.sinc(half / np.pi)


def constant_rollout(
    x: np.ndarray,
    y: np.ndarray,
    v: np.ndarray,
    phi: np.ndarray,
    action: np.ndarray,
    lim: Limits,
    dt_s: float,
    steps: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 5-6 integrated as the world does, ``steps`` steps of one constant action per vehicle.

    ``x, y, v, phi`` are (M,), ``action`` (M, 2) [omega, u] in [-1, 1] (clipped). Returns the states after
    steps 1..steps, each (M, steps). With a constant u the speed after k steps is clip(v + k u a dt) (the
    world clips each step; for a constant sign of u that is the same), and each step's displacement is the
    chord of its arc at the step's mean speed, v_m dt sinc(omega dt / 2) along phi + omega dt / 2: one
    cumulative sum instead of a loop.
    """
    a = np.clip(action, -1.0, 1.0)
    theta = a[:, 0] * lim.turn_rate_max_rad_s * dt_s  # heading change per step
    dv = a[:, 1] * lim.accel_max_m_s2 * dt_s
    k = np.arange(steps + 1, dtype=np.float64)
    speeds = np.clip(
        v[:, None] + k * dv[:, None], lim.speed_min_m_s[:, None], lim.speed_max_m_s[:, None]
    )  # (M, steps+1)
    headings = phi[:, None] + k * theta[:, None]
    chord = 0.5 * (speeds[:, :-1] + speeds[:, 1:]) * dt_s * _sinc(0.5 * theta)[:, None]
    mid = headings[:, :-1] + 0.5 * theta[:, None]
    xs = x[:, None] + np.cumsum(chord * np.cos(mid), axis=1)
    ys = y[:, None] + np.cumsum(chord * np.sin(mid), axis=1)
    return xs, ys, speeds[:, 1:], headings[:, 1:]


def step_actions(
    x: np.ndarray, y: np.ndarray, v: np.ndarray, phi: np.ndarray, actions: np.ndarray, lim: Limits, dt_s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fly a queue of actions, one per step: ``actions`` (M, L, 2). Returns the state after the last, (M,) each."""
    for j in range(actions.shape[1]):
        xs, ys, vs, ps = constant_rollout(x, y, v, phi, actions[:, j], lim, dt_s, 1)
        x, y, v, phi = xs[:, 0], ys[:, 0], vs[:, 0], ps[:, 0]
    return x, y, v, phi


# -------------------------------------------------------------------------------- clearance


def point_clearance(xs: np.ndarray, ys: np.ndarray, hz: Hazards) -> np.ndarray:
    """Distance of points (M, S) to the nearest radar disk's edge or area edge (negative: inside / outside), (M, S)."""
    a = hz.area_m
    edge = np.minimum(np.minimum(xs, a - xs), np.minimum(ys, a - ys))
    dx = xs[:, :, None] - hz.centres_m[:, None, :, 0]
    dy = ys[:, :, None] - hz.centres_m[:, None, :, 1]
    radar = np.hypot(dx, dy, out=dx)  # the monitor's hottest loop: in place, and an unused slot's radius -inf
    radar -= np.where(hz.radii_m > 0, hz.radii_m, -np.inf)[:, None, :]
    return np.minimum(edge, radar.min(axis=2, initial=np.inf))


def circle_clearance(cx: np.ndarray, cy: np.ndarray, r: np.ndarray, hz: Hazards) -> np.ndarray:
    """Clearance of whole circles (centres (M,), radii (M,)) from every disk and edge: exact, (M,)."""
    a = hz.area_m
    edge = np.minimum(np.minimum(cx, a - cx), np.minimum(cy, a - cy)) - r
    d = np.hypot(cx[:, None] - hz.centres_m[:, :, 0], cy[:, None] - hz.centres_m[:, :, 1])
    radar = np.where(hz.radii_m > 0, d - hz.radii_m - r[:, None], np.inf)
    return np.minimum(edge, radar.min(axis=1, initial=np.inf))


def brake_steps(lim: Limits, dt_s: float) -> int:
    """World steps after which a braking backup has reached v_min from any speed: ceil((v_max - v_min) / (a dt))."""
    return int(np.ceil(np.max((lim.speed_max_m_s - lim.speed_min_m_s) / (lim.accel_max_m_s2 * dt_s)) - 1e-9))


def segment_clearance(px: np.ndarray, py: np.ndarray, qx: np.ndarray, qy: np.ndarray, hz: Hazards) -> np.ndarray:
    """Clearance of whole straight segments P -> Q (M,) from every disk and edge: exact, (M,).

    The distance to an edge is linear along a segment, so its least value is at an end (the area is convex)."""
    a = hz.area_m
    edge = np.minimum.reduce([px, a - px, py, a - py, qx, a - qx, qy, a - qy])
    dx, dy = (qx - px)[:, None], (qy - py)[:, None]
    cx, cy = hz.centres_m[:, :, 0] - px[:, None], hz.centres_m[:, :, 1] - py[:, None]
    length2 = dx * dx + dy * dy
    t = np.clip((cx * dx + cy * dy) / np.maximum(length2, 1e-12), 0.0, 1.0)
    radar = np.hypot(cx - t * dx, cy - t * dy) - hz.radii_m
    radar = np.where(hz.radii_m > 0, radar, np.inf)
    return np.minimum(edge, radar.min(axis=1, initial=np.inf))


def lead_steps(cfg: ShieldConfig, dt_s: float) -> np.ndarray:
    """Each straight lead in world steps, (L,): the same whatever the decision interval, so that the backups a start
    was admitted with are the ones the first decision has, for a pilot deciding every tick or every 40 s alike. A
    lead may end between two decisions: the backup's command then changes there (:attr:`Decision.straight_steps`)."""
    return np.array([round(t / dt_s) for t in cfg.straight_leads_s], dtype=np.int64)


def _lead_ends(v: np.ndarray, u: float, lim: Limits, dt_s: float, leads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance flown straight and the speed at the end of each lead, (M, L) each: the world's steps at the
    mean of each step's speeds, the speed clipped to its bounds (a constant u: clip(v + k u a dt))."""
    k = np.arange(int(leads.max()) + 1, dtype=np.float64)
    speeds = np.clip(
        v[:, None] + k * (u * lim.accel_max_m_s2 * dt_s)[:, None],
        lim.speed_min_m_s[:, None],
        lim.speed_max_m_s[:, None],
    )
    travelled = np.concatenate(
        [np.zeros((len(v), 1)), np.cumsum(0.5 * (speeds[:, :-1] + speeds[:, 1:]) * dt_s, axis=1)], axis=1
    )
    return travelled[:, leads], speeds[:, leads]


def backup_clearance(
    x: np.ndarray,
    y: np.ndarray,
    v: np.ndarray,
    phi: np.ndarray,
    hz: Hazards,
    lim: Limits,
    dt_s: float,
    leads: np.ndarray,
    brake: np.ndarray | None = None,
) -> np.ndarray:
    """Clearance of every backup flown from each state for ever, (M, L * N_TURNS) (candidate lead * N_TURNS + turn).

    A backup flies straight for its lead (u = the turn's u), then its turn for ever. The lead is a straight
    segment (exact clearance); a constant-speed turn is a circle of radius v / omega_max (exact); a braking
    turn is a spiral (the world's samples, less v_max dt / 2) that ends on the circle of radius
    v_min / omega_max. ``brake`` (M,) bool: evaluate the braking backups only there (-inf elsewhere).
    """
    m, n_leads = len(x), len(leads)
    out = np.full((m, n_leads, N_TURNS), -np.inf)
    cos, sin = np.cos(phi), np.sin(phi)
    for u in (0.0, -1.0):
        rows = np.arange(m) if u == 0.0 or brake is None else np.flatnonzero(brake)
        if rows.size == 0:
            continue
        r_lim, r_hz = lim.select(rows), hz.select(rows)
        px, py, pc, ps = x[rows], y[rows], cos[rows], sin[rows]
        dist, qv = _lead_ends(v[rows], u, r_lim, dt_s, leads)  # (R, L)
        qx, qy = px[:, None] + dist * pc[:, None], py[:, None] + dist * ps[:, None]
        # Every lead of every row as one batch of R * L segments (a lead of 0 is a point: its own clearance).
        rep = np.repeat(np.arange(len(rows)), n_leads)
        b_hz, b_lim = r_hz.select(rep), r_lim.select(rep)
        bx, by, bc, bs = np.repeat(px, n_leads), np.repeat(py, n_leads), np.repeat(pc, n_leads), np.repeat(ps, n_leads)
        ex, ey, ev = qx.reshape(-1), qy.reshape(-1), qv.reshape(-1)
        lead = np.where(dist.reshape(-1) > 0, segment_clearance(bx, by, ex, ey, b_hz), np.inf)
        for j in (0, 1) if u == 0.0 else (2, 3):
            sign = TURNS[j, 0]
            if u == 0.0:  # the circle from the end of the lead
                r = ev / b_lim.turn_rate_max_rad_s
                turn = circle_clearance(ex - sign * r * bs, ey + sign * r * bc, r, b_hz)
            else:
                n = brake_steps(b_lim, dt_s)
                xs, ys, _, hs = constant_rollout(
                    ex, ey, ev, np.arctan2(bs, bc), np.broadcast_to(TURNS[j], (len(ex), 2)), b_lim, dt_s, n
                )
                spiral = point_clearance(xs, ys, b_hz).min(axis=1) - b_lim.speed_max_m_s * dt_s / 2
                r = b_lim.speed_min_m_s / b_lim.turn_rate_max_rad_s  # after n steps v = v_min
                circle = circle_clearance(
                    xs[:, -1] - sign * r * np.sin(hs[:, -1]), ys[:, -1] + sign * r * np.cos(hs[:, -1]), r, b_hz
                )
                turn = np.minimum(spiral, circle)
            out[rows, :, j] = np.minimum(lead, turn).reshape(len(rows), n_leads)
    return out.reshape(m, n_leads * N_TURNS)


def choose_backup(excess: np.ndarray) -> np.ndarray:
    """Which backup to remember, (M,), from each backup's excess over what it must keep (clearance less the
    margin and the error bound, (M, C)): among those with excess >= 0 the shortest lead, at constant speed
    before braking, then the clearest; when none has, the clearest of all."""
    n_cand = excess.shape[1]
    lead_i, turn_j = np.divmod(np.arange(n_cand), N_TURNS)
    rank = lead_i * 2 + (TURNS[turn_j, 1] != 0)  # lower is preferred
    clear = excess >= 0
    key = np.where(clear, rank * 1e7 - np.minimum(excess, 1e6), np.inf)
    return np.where(clear.any(axis=1), np.argmin(key, axis=1), np.argmax(excess, axis=1))


def backup_error_m(
    err: EstimateError, lim: Limits, dt_s: float, leads: np.ndarray, turned_steps_max: int | None = None
) -> np.ndarray:
    """How much of each backup's clearance the state's error can take away, (M, L * N_TURNS), in metres.

    A backup is open loop (a fixed sequence of commands in time), so flown from a state off by (d_p, d_phi, d_v)
    its whole path is the predicted one moved by d_p, turned about its start by d_phi, and flown at a speed off
    by at most d_v until the speed reaches a bound. With T the lead's time, w = omega_max, a = a_max:

    * constant speed (a lead of v T, then the circle of radius r = v / w, r <= v_max / w): the lead's segment moves
      by at most d_p + v_max T d_phi + T d_v; the circle's centre (at most v T + r from the start) by
      d_p + (v_max T + v_max / w) d_phi + (T + 1 / w) d_v, and its radius by d_v / w;
    * braking (the speed falls at a from v to v_min within t_b = (v_max - v_min) / a, while turning; then the
      circle of radius v_min / w): every point lies within v_max (T + t_b) + v_min / w of the start, and two speeds
      d_v apart fly at most d_v (T + t_b) apart before both reach v_min.

    The clearance of a moved path is at least the clearance of the predicted one less the largest move, which
    is what this returns per backup (candidate lead * N_TURNS + turn, as :func:`backup_clearance`).

    With ``turned_steps_max``, a backup whose lead holds its course after that many steps
    (:func:`~tssac_core.assurance.lagged_backups.held_rollout`) is turned by d_phi over those steps only: the line it
    then holds keeps the course the check predicted, so it is the predicted one moved, not turned further; d_p and
    d_v move it as before.
    """
    t = leads.astype(np.float64) * dt_s  # (L,)
    turned = t if turned_steps_max is None else np.minimum(t, turned_steps_max * dt_s)
    w, vmax = lim.turn_rate_max_rad_s[:, None], lim.speed_max_m_s[:, None]
    t_brake = ((lim.speed_max_m_s - lim.speed_min_m_s) / lim.accel_max_m_s2)[:, None]
    r_min = (lim.speed_min_m_s / lim.turn_rate_max_rad_s)[:, None]
    lever_const = vmax * turned[None, :] + vmax / w  # (M, L) metres of path per radian of heading error
    time_const = t[None, :] + 2.0 / w  # metres per m/s of speed error (centre and radius)
    lever_brake = vmax * (turned[None, :] + t_brake) + r_min
    time_brake = t[None, :] + t_brake
    out = np.empty((len(err.position_m), len(leads), N_TURNS))
    for j in range(N_TURNS):
        braking = TURNS[j, 1] != 0
        lever, secs = (lever_brake, time_brake) if braking else (lever_const, time_const)
        out[:, :, j] = err.position_m[:, None] + err.heading_rad[:, None] * lever + err.speed_m_s[:, None] * secs
    return out.reshape(len(err.position_m), len(leads) * N_TURNS)


def backup_action(backup: np.ndarray, lead_left: np.ndarray) -> np.ndarray:
    """The command a backup flies now, (M, 2): straight ([0, u]) during its lead, then its turn."""
    turn = TURNS[backup % N_TURNS]
    return np.where((lead_left > 0)[:, None], np.stack([np.zeros(len(turn)), turn[:, 1]], axis=1), turn)


# ------------------------------------------------------------------------------- prediction


@dataclass(frozen=True)
class Scene:
    """What every path of one decision is judged against: the hazards, the limits, the world step, the margin to keep
    ((M,)) and the monitor's configuration."""

    hz: Hazards
    lim: Limits
    dt_s: float
    margin: np.ndarray
    cfg: ShieldConfig

    def select(self, rows: np.ndarray) -> Scene:
        return Scene(self.hz.select(rows), self.lim.select(rows), self.dt_s, self.margin[rows], self.cfg)


class Prediction(Protocol):
    """How the monitor predicts a vehicle's paths: eq. 5-6 (:class:`KinematicPrediction`, the default) or an
    airframe's fitted response (:class:`tssac_core.assurance.lagged_prediction.LaggedPrediction`). States are (M,)
    arrays x, y, v, phi."""

    def select(self, rows: np.ndarray) -> Prediction:
        """The prediction of vehicles ``rows`` alone."""
        ...

    def after(
        self, x: np.ndarray, y: np.ndarray, v: np.ndarray, phi: np.ndarray, pending: np.ndarray, scene: Scene
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Prediction]:
        """The state after the ``pending`` (M, L, 2) actions, and the prediction from there."""
        ...

    def proposal_excess(
        self,
        x: np.ndarray,
        y: np.ndarray,
        v: np.ndarray,
        phi: np.ndarray,
        proposed: np.ndarray,
        steps: int,
        err_end: EstimateError,
        scene: Scene,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The proposed action as flown, the excess of its path and best backup, and that backup (as
        :func:`_proposal_excess`)."""
        ...

    def backup_excess(
        self, x: np.ndarray, y: np.ndarray, v: np.ndarray, phi: np.ndarray, err: EstimateError, scene: Scene
    ) -> np.ndarray:
        """Every backup's excess from the states themselves, (M, L * N_TURNS) (as :func:`_backup_excess_here`)."""
        ...

    def backup_error(self, err: EstimateError, scene: Scene) -> np.ndarray:
        """How much of each offered backup's clearance the error ``err`` takes away, (M, L * N_TURNS) metres (0 for a
        backup not offered)."""
        ...

    def held_from_steps(self, dt_s: float) -> int | None:
        """The step of a lead from which it holds its course (None: every lead is flown open loop)."""
        ...

    def held_course(
        self, x: np.ndarray, y: np.ndarray, v: np.ndarray, phi: np.ndarray, backup: np.ndarray, scene: Scene
    ) -> np.ndarray:
        """The course each ``backup`` (candidate index) flown from the states holds after its lead's open part, (M,)
        rad; NaN where its lead is flown open loop to its end."""
        ...


class KinematicPrediction:
    """Eq. 5-6, as the batched world and the kinematic SITL fly: the module docstring's proof."""

    def select(self, rows: np.ndarray) -> Prediction:
        return self

    def after(
        self, x: np.ndarray, y: np.ndarray, v: np.ndarray, phi: np.ndarray, pending: np.ndarray, scene: Scene
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Prediction]:
        return (*step_actions(x, y, v, phi, pending, scene.lim, scene.dt_s), self)

    def proposal_excess(
        self,
        x: np.ndarray,
        y: np.ndarray,
        v: np.ndarray,
        phi: np.ndarray,
        proposed: np.ndarray,
        steps: int,
        err_end: EstimateError,
        scene: Scene,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        sc = scene
        return _proposal_excess(x, y, v, phi, proposed, sc.hz, sc.lim, sc.dt_s, steps, sc.margin, err_end, sc.cfg)

    def backup_excess(
        self, x: np.ndarray, y: np.ndarray, v: np.ndarray, phi: np.ndarray, err: EstimateError, scene: Scene
    ) -> np.ndarray:
        rows = np.ones(len(x), bool)
        leads = lead_steps(scene.cfg, scene.dt_s)
        sc = scene
        return _backup_excess_here(x, y, v, phi, rows, sc.hz, sc.lim, sc.dt_s, leads, sc.margin, err, sc.cfg)

    def backup_error(self, err: EstimateError, scene: Scene) -> np.ndarray:
        return backup_error_m(err, scene.lim, scene.dt_s, lead_steps(scene.cfg, scene.dt_s))

    def held_from_steps(self, dt_s: float) -> int | None:
        return None  # eq. 5's straight leads are exact: every one is flown open loop

    def held_course(
        self, x: np.ndarray, y: np.ndarray, v: np.ndarray, phi: np.ndarray, backup: np.ndarray, scene: Scene
    ) -> np.ndarray:
        return np.full(len(x), np.nan)


KINEMATIC = KinematicPrediction()


# --------------------------------------------------------------------------------- decision


def _proposal_excess(
    x: np.ndarray,
    y: np.ndarray,
    v: np.ndarray,
    phi: np.ndarray,
    proposed: np.ndarray,
    hz: Hazards,
    lim: Limits,
    dt_s: float,
    steps: int,
    margin: np.ndarray,
    err_end: EstimateError,
    cfg: ShieldConfig,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The proposed action held ``steps`` steps from the state where it starts: (a) its path's excess over the margin
    and (b) each backup's from where it ends. Returns the action as flown (clipped; a row that is not finite held at
    0), the excess of the whole (the lesser of the path's and the best backup's; -inf for a row that is not finite)
    and the best backup's index."""
    m = len(x)
    leads = lead_steps(cfg, dt_s)
    raw = np.asarray(proposed, dtype=np.float64)
    finite: np.ndarray = np.all(np.isfinite(raw), axis=1)
    proposed = np.clip(np.where(finite[:, None], raw, 0.0), -1.0, 1.0)
    xs, ys, vs, ps = constant_rollout(x, y, v, phi, proposed, lim, dt_s, steps)
    # (a) the path's excess over the margin; err_end bounds the path's error over the whole interval.
    path = point_clearance(xs, ys, hz).min(axis=1) - lim.speed_max_m_s * dt_s / 2 - margin - err_end.position_m
    path = np.where(finite, path, -np.inf)
    ex, ey, ev, ep = xs[:, -1], ys[:, -1], vs[:, -1], ps[:, -1]
    # (b) each backup's excess from the end state. The braking backups (a 150-step spiral each) only where no
    # constant-speed one clears the release margin.
    end_error = backup_error_m(err_end, lim, dt_s, leads)
    ends = backup_clearance(ex, ey, ev, ep, hz, lim, dt_s, leads, brake=np.zeros(m, bool)) - margin[:, None] - end_error
    need_brake = (ends.max(axis=1) < cfg.release_margin_m) & (path >= 0) & cfg.braking_backups
    if need_brake.any():
        braking = backup_clearance(ex, ey, ev, ep, hz, lim, dt_s, leads, brake=need_brake)
        ends = np.maximum(ends, braking - margin[:, None] - end_error)
    best_end = choose_backup(ends)
    excess = np.minimum(path, ends.max(axis=1))
    return proposed, excess, best_end


def decide(
    state: np.ndarray,
    proposed: np.ndarray,
    memory: Memory,
    hz: Hazards,
    lim: Limits,
    dt_s: float,
    steps: int,
    margin_m: np.ndarray | float,
    cfg: ShieldConfig,
    pending: np.ndarray | None = None,
    error: EstimateError | None = None,
    prediction: Prediction = KINEMATIC,
) -> Decision:
    """One decision of the monitor for M vehicles.

    ``state`` (M, 4): the estimate x, y, v, phi now; ``proposed`` (M, 2) the policy's action, to be held for
    ``steps`` world steps of ``dt_s`` (a row that is not finite never passes: the backup flies); ``pending``
    (M, L, 2) the commands already sent that the vehicle will fly first (the link's latency; None or L = 0 in the
    batched world); ``margin_m`` scalar or (M,) the clearance to keep (:attr:`ShieldConfig.margin_m`, plus the
    timing slack off lockstep); ``error`` the bounds on the estimate's error (None: the true state, as in the
    batched world), taken off every path's and backup's clearance as :func:`backup_error_m` says; ``prediction`` how
    the paths are predicted (eq. 5-6 unless an airframe's response is given)."""
    margin = np.broadcast_to(np.asarray(margin_m, dtype=np.float64), (len(state),))
    scene = Scene(hz, lim, dt_s, margin, cfg)
    err_now = EstimateError.zero(len(state)) if error is None else error
    x, y, v, phi = (np.asarray(state[:, i], dtype=np.float64) for i in range(4))
    n_pending = 0 if pending is None else pending.shape[1]
    if n_pending:
        assert pending is not None
        x, y, v, phi, prediction = prediction.after(x, y, v, phi, pending, scene)
    err_here = err_now.after(n_pending * dt_s, lim)  # at the state the next command starts from
    err_end = err_now.after((n_pending + steps) * dt_s, lim)  # at the end of the proposed action's interval
    leads = lead_steps(cfg, dt_s)
    finite = np.all(np.isfinite(np.asarray(proposed, dtype=np.float64)), axis=1)
    proposed, excess, best_end = prediction.proposal_excess(x, y, v, phi, proposed, steps, err_end, scene)
    engaged, protected = memory.engaged, memory.protected
    # A finite proposal that fails while the policy flies: the nearest passing candidate first (cfg.adjust).
    rows = finite & (excess < 0) & ~engaged & cfg.adjust
    proposed, excess, best_end, adjusted = _nearest_passing(
        prediction, x, y, v, phi, (proposed, excess, best_end), steps, err_end, scene, rows
    )
    passes, passes_release = excess >= 0, excess >= cfg.release_margin_m
    backup, lead_left = memory.backup.copy(), memory.lead_left.copy()
    count = np.where(engaged & passes_release, memory.passes + 1, 0)
    # An unprotected vehicle has no guarantee to keep: any passing action is better than its backup.
    release = engaged & ((count >= cfg.release_decisions) | (passes & ~protected))
    fly_proposed = (~engaged & passes) | release
    # A vehicle with no known backup (its first decision failed) takes the clearest one from where it is.
    lost = ~fly_proposed & ~protected
    protected = protected.copy()
    if lost.any():
        backup[lost], lead_left[lost], protected[lost] = _clearest(prediction, lost, (x, y, v, phi), err_here, scene)
    held_course = _held_courses(
        prediction, (x, y, v, phi), proposed, steps, (backup, best_end, lost, fly_proposed), memory, scene
    )
    now_engaged = ~fly_proposed
    action = np.where(now_engaged[:, None], backup_action(backup, lead_left), proposed)
    straight_steps = np.where(now_engaged, np.minimum(lead_left, steps), steps)
    lead_left = np.where(now_engaged, np.maximum(lead_left - steps, 0), leads[best_end // N_TURNS])
    new_memory = Memory(
        engaged=now_engaged,
        protected=np.where(fly_proposed, True, protected),
        backup=np.where(fly_proposed, best_end, backup),
        lead_left=lead_left,
        passes=np.where(now_engaged, count, 0),
        held_course=held_course,
    )
    return Decision(
        action=action,
        memory=new_memory,
        engaged=now_engaged,
        adjusted=fly_proposed & adjusted,
        engaged_now=~engaged & ~passes,
        released_now=release,
        unprotected=now_engaged & ~new_memory.protected,
        clearance_m=excess + margin,
        straight_steps=straight_steps,
        turn=TURNS[backup % N_TURNS],
    )


ADJUST_TURNS = np.linspace(-1.0, 1.0, 9)
"""The turn rates (of the limit) the adjusted candidates try beside the proposal's own."""


def adjusted_candidates(proposed: np.ndarray) -> np.ndarray:
    """The actions the monitor tries when a proposal (M, 2) fails, (M, C, 2): the proposal's turn rate and every one of
    :data:`ADJUST_TURNS`, each at the proposal's acceleration, at constant speed (a constant-speed backup's first
    command is one of them) and braking at the limit."""
    m = len(proposed)
    turns = np.concatenate([proposed[:, :1], np.repeat(ADJUST_TURNS[None, :], m, axis=0)], axis=1)
    accels = np.stack([proposed[:, 1], np.zeros(m), np.full(m, -1.0)], axis=1)
    grid = np.broadcast_arrays(turns[:, :, None], accels[:, None, :])
    return np.stack(grid, axis=-1).reshape(m, -1, 2)


def _nearest_passing(
    prediction: Prediction,
    x: np.ndarray,
    y: np.ndarray,
    v: np.ndarray,
    phi: np.ndarray,
    flown: tuple[np.ndarray, np.ndarray, np.ndarray],
    steps: int,
    err_end: EstimateError,
    scene: Scene,
    rows: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The proposals as flown, their excesses and best backups (``flown``), with the passing candidate
    (:func:`adjusted_candidates`) nearest the proposal in place for the vehicles ``rows`` (a bool mask) where one
    passes, nearness |d omega| + |d u| / 2; and which vehicles those are."""
    adjusted = np.zeros(len(flown[0]), bool)
    idx = np.flatnonzero(rows)
    if not len(idx):  # the plain monitor, or nothing failed: no copies on the hot path
        return (*flown, adjusted)
    proposed, excess, best_end = (a.copy() for a in flown)
    cand = adjusted_candidates(proposed[idx])
    r, c = cand.shape[:2]
    rep = np.repeat(idx, c)
    _, cand_excess, cand_best = prediction.select(rep).proposal_excess(
        x[rep], y[rep], v[rep], phi[rep], cand.reshape(-1, 2), steps, err_end.select(rep), scene.select(rep)
    )
    cand_excess, cand_best = cand_excess.reshape(r, c), cand_best.reshape(r, c)
    distance = np.abs(cand - proposed[idx, None, :]) @ np.array([1.0, 0.5])
    key = np.where(cand_excess >= 0, distance, np.inf)
    pick = np.argmin(key, axis=1)
    at = np.arange(r)
    found = np.isfinite(key[at, pick])
    take = idx[found]
    proposed[take], excess[take], best_end[take] = (
        cand[at, pick][found],
        cand_excess[at, pick][found],
        cand_best[at, pick][found],
    )
    adjusted[take] = True
    return proposed, excess, best_end, adjusted


def _held_courses(
    prediction: Prediction,
    state: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    proposed: np.ndarray,
    steps: int,
    chosen: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    memory: Memory,
    scene: Scene,
) -> np.ndarray:
    """The course each vehicle's backup holds after its lead's open part, as its check predicted it (NaN: none):
    ``chosen`` = (the backup kept for a flying or lost vehicle, the best backup from the end of the proposal's interval,
    the lost vehicles, the vehicles whose proposal flies), bool masks the last two. A lost vehicle's backup starts
    where it is; a flying proposal's, where its interval ends; a flying backup keeps its course. Computed only where a
    held lead was chosen (none with eq. 5)."""
    backup, best_end, lost, fly_proposed = chosen
    out = memory.held_course.copy()
    held_from = prediction.held_from_steps(scene.dt_s)
    if held_from is None:
        return np.where(fly_proposed | lost, np.nan, out)
    leads = lead_steps(scene.cfg, scene.dt_s)
    out[lost | fly_proposed] = np.nan
    x, y, v, phi = state
    rows = lost & (leads[backup // N_TURNS] > held_from)
    if rows.any():
        sub = prediction.select(rows)
        out[rows] = sub.held_course(x[rows], y[rows], v[rows], phi[rows], backup[rows], scene.select(rows))
    rows = fly_proposed & (leads[best_end // N_TURNS] > held_from)
    if rows.any():
        sub, sub_scene = prediction.select(rows), scene.select(rows)
        flown = np.repeat(np.asarray(proposed, dtype=np.float64)[rows][:, None, :], steps, axis=1)
        ex, ey, ev, ep, end = sub.after(x[rows], y[rows], v[rows], phi[rows], flown, sub_scene)
        out[rows] = end.held_course(ex, ey, ev, ep, best_end[rows], sub_scene)
    return out


def _clearest(
    prediction: Prediction,
    rows: np.ndarray,
    state: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    err: EstimateError,
    scene: Scene,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For the vehicles ``rows`` (a bool mask), which have no known backup: the clearest one from where each is (the
    monitor's choice among every backup's excess), its lead's steps, and whether it clears."""
    x, y, v, phi = (a[rows] for a in state)
    here = prediction.select(rows).backup_excess(x, y, v, phi, err.select(rows), scene.select(rows))
    pick = choose_backup(here)
    return pick, lead_steps(scene.cfg, scene.dt_s)[pick // N_TURNS], here[np.arange(len(here)), pick] >= 0


def _backup_excess_here(
    x: np.ndarray,
    y: np.ndarray,
    v: np.ndarray,
    phi: np.ndarray,
    rows: np.ndarray,
    hz: Hazards,
    lim: Limits,
    dt_s: float,
    leads: np.ndarray,
    margin: np.ndarray,
    err: EstimateError,
    cfg: ShieldConfig,
) -> np.ndarray:
    """Every backup's excess over the margin and the error bound, flown from the states ``rows`` (a bool mask)
    themselves, (R, L * N_TURNS): a vehicle with no remembered backup, and the start check."""
    sub_hz, sub_lim = hz.select(rows), lim.select(rows)
    sub_err = EstimateError(err.position_m[rows], err.heading_rad[rows], err.speed_m_s[rows])
    clearance = backup_clearance(
        x[rows],
        y[rows],
        v[rows],
        phi[rows],
        sub_hz,
        sub_lim,
        dt_s,
        leads,
        brake=np.full(int(rows.sum()), cfg.braking_backups),
    )
    return clearance - margin[rows, None] - backup_error_m(sub_err, sub_lim, dt_s, leads)


def start_excess_m(
    state: np.ndarray,
    hz: Hazards,
    lim: Limits,
    dt_s: float,
    cfg: ShieldConfig,
    margin_m: np.ndarray | float,
    hold_steps: int = 0,
    error: EstimateError | None = None,
) -> np.ndarray:
    """How far each start (M, 4: x, y, v, phi) is inside what the monitor admits, (M,) metres; >= 0: admitted.

    The monitor's induction covers every state from which some backup is clear; the first state is the one it
    cannot choose. A start is admitted if, after ``hold_steps`` steps of the hold command (straight on at
    constant speed: what the vehicle flies before the first command reaches it, a round trip of the link), the
    hold's path keeps the margin and some backup from its end keeps it for ever, both after the error bound:
    exactly what the first decision finds when the proposed action fails (the remembered backup is then the
    clearest of those). From an admitted start, the monitor keeps the UAV out of every radar and inside the area
    whatever the policy proposes, and whatever its decision interval: the backups' leads do not depend on it
    (:func:`lead_steps`).
    """
    m = len(state)
    margin = np.broadcast_to(np.asarray(margin_m, dtype=np.float64), (m,))
    err0 = EstimateError.zero(m) if error is None else error
    x, y, v, phi = (np.asarray(state[:, i], dtype=np.float64) for i in range(4))
    hold_path = np.full(m, np.inf)
    if hold_steps:
        xs, ys, vs, ps = constant_rollout(x, y, v, phi, np.zeros((m, 2)), lim, dt_s, hold_steps)
        here_err = err0.after(hold_steps * dt_s, lim)
        hold_path = (
            point_clearance(xs, ys, hz).min(axis=1) - lim.speed_max_m_s * dt_s / 2 - margin - here_err.position_m
        )
        x, y, v, phi = xs[:, -1], ys[:, -1], vs[:, -1], ps[:, -1]
    else:
        here_err = err0
    leads = lead_steps(cfg, dt_s)
    # The constant-speed backups first (circles: cheap); the braking ones (spirals) only where none of those do.
    best = (
        backup_clearance(x, y, v, phi, hz, lim, dt_s, leads, brake=np.zeros(m, bool))
        - margin[:, None]
        - backup_error_m(here_err, lim, dt_s, leads)
    ).max(axis=1)
    short = best < 0
    if short.any() and cfg.braking_backups:
        best[short] = _backup_excess_here(x, y, v, phi, short, hz, lim, dt_s, leads, margin, here_err, cfg).max(axis=1)
    return np.minimum(hold_path, best)


def handover_error(lim: Limits, dt_s: float, ticks: int) -> EstimateError:
    """The error bound a command change can add when its first ``ticks`` setpoints are lost or late: the vehicle
    flies the previous command (any [omega, u]) that long instead. Two commands differ by at most 2 omega_max and
    2 a_max, so after t = ticks dt the heading differs by at most 2 omega_max t, the speed by 2 a_max t, and the
    position by at most (a_max + v_max omega_max) t^2; and a backup's turn that starts t late is its circle moved
    v_max t along the lead."""
    t = ticks * dt_s
    w, a, vmax = lim.turn_rate_max_rad_s, lim.accel_max_m_s2, lim.speed_max_m_s
    return EstimateError((a + vmax * w) * t * t + vmax * t, 2.0 * w * t, 2.0 * a * t)


def companion_margin_m(cfg: ShieldConfig, speed_max_m_s: float, off_lockstep: bool) -> float:
    """A companion's margin: the base, and off lockstep v_max times the timing slack (a companion that falls
    behind the vehicle's clock). The estimate's error is not in it but in :func:`companion_error`, per backup."""
    return cfg.margin_m + (speed_max_m_s * cfg.timing_slack_s if off_lockstep else 0.0)


def companion_error(
    cfg: ShieldConfig,
    lim: Limits,
    dt_s: float,
    position_sigma_major_m: float,
    heading_sigma_rad: float,
    speed_sigma_m_s: float,
    lossy: bool,
) -> EstimateError:
    """A companion's error bound for one vehicle: ``sigma_k`` standard deviations of the Kalman filter's position
    (its covariance's major axis), heading and speed, and with ``lossy`` (a link that loses packets, or a
    companion off lockstep) :attr:`ShieldConfig.handover_ticks` setpoints lost or late at a command change."""
    k = cfg.sigma_k
    est = EstimateError(
        np.array([k * max(0.0, position_sigma_major_m)]),
        np.array([k * max(0.0, heading_sigma_rad)]),
        np.array([k * max(0.0, speed_sigma_m_s)]),
    )
    return est + handover_error(lim, dt_s, cfg.handover_ticks if lossy else 0)


def largest_backup_error_m(err: EstimateError, steps: int, scene: Scene, prediction: Prediction = KINEMATIC) -> float:
    """The most clearance the error bound takes from any backup the prediction offers at the end of a decision
    interval of ``steps`` (a report)."""
    return float(prediction.backup_error(err.after(steps * scene.dt_s, scene.lim), scene).max())
