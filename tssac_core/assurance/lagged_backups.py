"""The monitor's prediction with an airframe's response: the turn-rate lag, and a keep-out region for every backup
that holds for ever under it (issue 58, the monitor under real dynamics; the model and its fitted data:
:mod:`tssac_core.sim.airframe_response`).

Pure numpy, vectorised over M vehicles, in the frames and units of :mod:`tssac_core.assurance.monitor`.

**The model** (per vehicle, at its speed). The heading rate follows the commanded one after ``d`` world steps
through a first-order lag, of time constant tau_out while it rolls out (the command asks for less turn the same way,
or none: a fixed wing rolls out of a turn faster than it rolls in) and tau otherwise (rolling in, or reversing): with
c_k the command the airframe follows over step k (the one sent d steps earlier), g = 1 - exp(-dt / tau) and
h = tau g / dt for the step's phase,

    mean rate over step k   m_k = c_k + (omega_k - c_k) h
    rate at its end         omega_k+1 = c_k + (omega_k - c_k) (1 - g)

and the position moves by eq. 5's exact arc at the mean rate (the chord v dt sinc(m dt / 2) along
phi + m dt / 2), as the fit flew it. The forward acceleration is the command clipped to what the airframe achieves
([decel, accel]). :class:`LagState` carries what the lag needs beyond eq. 5's state: the rate flown now and the
commands sent but not yet followed.

**A backup's keep-out region** (a constant-speed backup: straight for its lead, then a maximum-rate turn
omega_c = +-omega_max for ever). The lead and the turn's first ``K`` steps (the delay and four time constants) are
the model's own samples; an arc between two samples is never farther than v dt / 2 from one of them. After them, with
r = v / |omega_c| and the *instantaneous centre* c(t) = p(t) + r n(phi(t)) (n the unit normal toward the turn),

    dc/dt = v (1 - omega(t) / omega_c) u(phi)   so   |dc/dt| = r |omega(t) - omega_c|

and the gap after step K decays at least as |omega_K - omega_c| exp(-t / tau_max) (a first-order decay toward
omega_c; tau_max the longer of the two time constants): the centre moves at most
rho = r |omega_K - omega_c| tau_max in all, and the vehicle, always at r from c(t), stays for ever inside the disk of
radius r + rho about c_K. Its clearance is exact (:func:`~tssac_core.assurance.monitor.circle_clearance`); the
samples' clearance less v dt / 2 covers the rest. Against the real airframe the model is off by at most the fitted
``turn_residual_m`` (the largest distance the fit's turns and roll-outs left): taken off every clearance here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tssac_core.assurance.monitor import (
    Hazards,
    Limits,
    circle_clearance,
    point_clearance,
)

SETTLE_TIME_CONSTANTS = 4.0
"""A turn's samples run for the delay and this many time constants; the rest is the disk (its rho is then at most
exp(-4), under 2%, of the gap at the turn's start times r tau)."""


def lag_gains(taus: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """For time constants ``taus`` (s, >= 0): g = 1 - exp(-dt / tau), the share of the gap to the command closed in a
    step, and h = tau g / dt, the gap's share left in the step's mean rate (tau = 0: g = 1, h = 0, no lag)."""
    taus = np.asarray(taus, dtype=np.float64)
    safe = np.where(taus > 0.0, taus, 1.0)
    g = np.where(taus > 0.0, -np.expm1(-dt_s / safe), 1.0)
    h = np.where(taus > 0.0, safe * g / dt_s, 0.0)
    return g, h


def lag_step_mean(
    omega: np.ndarray, command: np.ndarray, g: np.ndarray, h: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """One step of the lag (module docstring): the rate's mean over the step and the rate at its end."""
    gap = omega - command
    return command + gap * h, command + gap * (1.0 - g)


def switched_lag_step(
    omega: np.ndarray,
    command: np.ndarray,
    gains_in: tuple[np.ndarray, np.ndarray],
    gains_out: tuple[np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """One step of the lag with one time constant rolling in and another rolling out (module docstring): while the
    command asks for less turn the same way or none (0 <= omega command, |command| < |omega|: rolling out toward it)
    the roll-out's gains (g, h), otherwise (rolling in, or reversing through zero) the roll-in's."""
    out = (omega * command >= 0.0) & (np.abs(command) < np.abs(omega))
    g = np.where(out, gains_out[0], gains_in[0])
    h = np.where(out, gains_out[1], gains_in[1])
    return lag_step_mean(omega, command, g, h)


@dataclass(frozen=True)
class AirframeLag:
    """The response of each vehicle's airframe at its speed, (M,) arrays (module docstring)."""

    delay_steps: np.ndarray
    """Whole world steps before a command is followed, int."""
    tau_s: np.ndarray
    """The lag's time constant rolling in or reversing (s, >= 0)."""
    rollout_tau_s: np.ndarray
    """The lag's time constant rolling out, toward a smaller turn the same way or none (s, >= 0): a fixed wing rolls
    out of a turn faster than it rolls in (the f16's roll-in waits for the load factor)."""
    accel_m_s2: np.ndarray
    """The largest forward acceleration it achieves (> 0)."""
    decel_m_s2: np.ndarray
    """The largest deceleration it achieves (< 0)."""
    residual_m: np.ndarray
    """How far the airframe's path may lie from the model's (m)."""
    held_residual_m: np.ndarray | None = None
    """How far the airframe's path may lie from the model's over a backup whose lead holds its course after
    ``held_after_s`` (m; None: no held leads, every lead flown open loop)."""
    held_after_s: float = 32.0
    """A lead longer than this holds, from this time on, the ground line through where the vehicle is then along the
    course the model predicts there (:func:`held_rollout`); shorter leads are flown open loop."""

    def select(self, idx: np.ndarray) -> AirframeLag:
        return AirframeLag(
            self.delay_steps[idx],
            self.tau_s[idx],
            self.rollout_tau_s[idx],
            self.accel_m_s2[idx],
            self.decel_m_s2[idx],
            self.residual_m[idx],
            None if self.held_residual_m is None else self.held_residual_m[idx],
            self.held_after_s,
        )

    def held_from_steps(self, dt_s: float) -> int | None:
        """The world step from which a long lead holds its course (None: no held leads)."""
        return None if self.held_residual_m is None else round(self.held_after_s / dt_s)

    def lead_residual_m(self, leads: np.ndarray, dt_s: float) -> np.ndarray:
        """The residual of each backup with each lead of ``leads`` (world steps), (M, L): the held one for the leads
        that hold their course, the turns' for the rest."""
        held_from = self.held_from_steps(dt_s)
        out = np.repeat(self.residual_m[:, None], len(leads), axis=1)
        if held_from is not None:
            assert self.held_residual_m is not None
            held = np.asarray(leads) > held_from
            out[:, held] = self.held_residual_m[:, None]
        return out

    def longest_tau_s(self) -> np.ndarray:
        """The longer of the two time constants, (M,)."""
        return np.maximum(self.tau_s, self.rollout_tau_s)

    def settle_steps(self, dt_s: float) -> int:
        """The turn's sampled steps K: the longest delay and SETTLE_TIME_CONSTANTS of the longest time constant."""
        return int(self.delay_steps.max(initial=0)) + math.ceil(
            SETTLE_TIME_CONSTANTS * self.longest_tau_s().max(initial=0) / dt_s
        )


@dataclass(frozen=True)
class LagState:
    """What the lag needs beyond x, y, v, phi, (M,) and (M, D) arrays."""

    omega_rad_s: np.ndarray
    """The heading rate flown now."""
    pending_rad_s: np.ndarray
    """(M, D) the heading-rate commands sent and not yet followed, oldest first; a vehicle whose delay d is shorter
    than D uses its last d columns (D >= every vehicle's delay)."""

    @staticmethod
    def steady(omega_rad_s: np.ndarray, width: int) -> LagState:
        """A vehicle in a steady turn at ``omega`` (0: straight), its last ``width`` commands that rate."""
        omega = np.asarray(omega_rad_s, dtype=np.float64)
        return LagState(omega.copy(), np.repeat(omega[:, None], width, axis=1))

    def select(self, idx: np.ndarray) -> LagState:
        return LagState(self.omega_rad_s[idx], self.pending_rad_s[idx])


@dataclass(frozen=True)
class Rollout:
    """A path flown under the model: the states after steps 1..S, (M, S) each, and what the lag needs after each."""

    xs: np.ndarray
    ys: np.ndarray
    speeds: np.ndarray
    headings: np.ndarray
    rates: np.ndarray
    """(M, S) the heading rate flown at the end of each step."""
    queue: np.ndarray
    """(M, D + S) the pending commands, then the ones flown: what is still pending after step k is columns
    k + 1 .. k + D."""

    def lag_after(self, steps: int) -> LagState:
        """The lag's state after ``steps`` steps (1..S)."""
        width = self.queue.shape[1] - self.rates.shape[1]
        return LagState(self.rates[:, steps - 1], self.queue[:, steps : steps + width])


def lagged_rollout(
    x: np.ndarray,
    y: np.ndarray,
    v: np.ndarray,
    phi: np.ndarray,
    lag_state: LagState,
    turn_commands_rad_s: np.ndarray,
    accel_commands_m_s2: np.ndarray,
    airframe: AirframeLag,
    lim: Limits,
    dt_s: float,
) -> Rollout:
    """Fly ``S`` steps of commands, (M, S) heading rates (rad/s) and accelerations (m/s^2), under the model (module
    docstring): the pending commands first, the acceleration clipped to [decel, accel] and the speed to its limits."""
    m, s = turn_commands_rad_s.shape
    width = lag_state.pending_rad_s.shape[1]
    queue = np.concatenate([lag_state.pending_rad_s, turn_commands_rad_s], axis=1)  # (M, D + S)
    start = width - airframe.delay_steps  # column of the command followed over step 0, (M,)
    if np.any(start < 0):
        raise ValueError(f"LagState: {width} pending commands, but a delay of {airframe.delay_steps.max()} steps")
    followed = np.take_along_axis(queue, start[:, None] + np.arange(s)[None, :], axis=1)  # (M, S)
    gains_in, gains_out = lag_gains(airframe.tau_s, dt_s), lag_gains(airframe.rollout_tau_s, dt_s)
    accel = np.clip(accel_commands_m_s2, airframe.decel_m_s2[:, None], airframe.accel_m_s2[:, None])
    omega = lag_state.omega_rad_s.astype(np.float64)
    px, py, pv, ph = (np.asarray(a, dtype=np.float64).copy() for a in (x, y, v, phi))
    out = np.empty((5, m, s))
    for k in range(s):
        rate, omega = switched_lag_step(omega, followed[:, k], gains_in, gains_out)
        v_next = np.clip(pv + accel[:, k] * dt_s, lim.speed_min_m_s, lim.speed_max_m_s)
        half = 0.5 * rate * dt_s
        chord = 0.5 * (pv + v_next) * dt_s * np.sinc(half / np.pi)
        px = px + chord * np.cos(ph + half)
        py = py + chord * np.sin(ph + half)
        ph = ph + rate * dt_s
        pv = v_next
        out[:, :, k] = px, py, pv, ph, omega
    return Rollout(out[0], out[1], out[2], out[3], out[4], queue)


def straight_rollout(
    x: np.ndarray,
    y: np.ndarray,
    v: np.ndarray,
    phi: np.ndarray,
    lag_state: LagState,
    steps: int,
    airframe: AirframeLag,
    lim: Limits,
    dt_s: float,
) -> Rollout:
    """:func:`lagged_rollout` of ``steps`` steps of straight flight (heading-rate command 0, speed held), the same
    path: the pending commands by the step, then, with nothing but zeros left to follow, the roll-out's closed form
    (the rate decays as omega (1 - g)^j, its step means omega (1 - g)^j h) in one pass instead of a step at a time."""
    m, width = len(x), lag_state.pending_rad_s.shape[1]
    first = min(steps, width)
    head = lagged_rollout(x, y, v, phi, lag_state, np.zeros((m, first)), np.zeros((m, first)), airframe, lim, dt_s)
    rest = steps - first
    if rest == 0:
        return head
    if first:
        x0, y0, v0, p0, w0 = (a[:, -1] for a in (head.xs, head.ys, head.speeds, head.headings, head.rates))
    else:
        x0, y0, p0, w0 = x, y, phi, lag_state.omega_rad_s
        v0 = np.clip(v, lim.speed_min_m_s, lim.speed_max_m_s)
    g, h = lag_gains(airframe.rollout_tau_s, dt_s)
    decay = (1.0 - g)[:, None] ** np.arange(rest)[None, :]  # (M, rest)
    means = w0[:, None] * decay * h[:, None]
    headings = p0[:, None] + np.cumsum(means * dt_s, axis=1)
    half = 0.5 * means * dt_s
    chord = v0[:, None] * dt_s * np.sinc(half / np.pi)
    mid = headings - half
    tail = (
        x0[:, None] + np.cumsum(chord * np.cos(mid), axis=1),
        y0[:, None] + np.cumsum(chord * np.sin(mid), axis=1),
        np.repeat(v0[:, None], rest, axis=1),
        headings,
        w0[:, None] * decay * (1.0 - g)[:, None],
    )
    parts = [
        np.concatenate([a, b], axis=1) for a, b in zip((head.xs, head.ys, head.speeds, head.headings, head.rates), tail)
    ]
    xs, ys, speeds, headings, rates = parts
    return Rollout(
        xs, ys, speeds, headings, rates, np.concatenate([lag_state.pending_rad_s, np.zeros((m, steps))], axis=1)
    )


def held_rollout(
    x: np.ndarray,
    y: np.ndarray,
    v: np.ndarray,
    phi: np.ndarray,
    lag_state: LagState,
    steps: int,
    held_from: int,
    airframe: AirframeLag,
    lim: Limits,
    dt_s: float,
) -> Rollout:
    """A lead of ``steps`` steps that flies straight open loop (:func:`straight_rollout`) for its first ``held_from``
    steps and then holds its course: the ground line through where the model is at step ``held_from``, along the
    model's heading there, flown at that speed, the lag steady and straight (rate 0, nothing pending). The airframe
    follows it under a line-following law; how far it may lie off is the fitted ``held_residual_m``."""
    first = min(steps, held_from)
    head = straight_rollout(x, y, v, phi, lag_state, first, airframe, lim, dt_s)
    rest = steps - first
    if rest == 0:
        return head
    m = len(x)
    if first:
        x0, y0, v0, p0 = (a[:, -1] for a in (head.xs, head.ys, head.speeds, head.headings))
    else:
        x0, y0, p0 = x, y, phi
        v0 = np.clip(v, lim.speed_min_m_s, lim.speed_max_m_s)
    along = v0[:, None] * dt_s * np.arange(1, rest + 1)[None, :]  # (M, rest)
    tail = (
        x0[:, None] + along * np.cos(p0)[:, None],
        y0[:, None] + along * np.sin(p0)[:, None],
        np.repeat(v0[:, None], rest, axis=1),
        np.repeat(p0[:, None], rest, axis=1),
        np.zeros((m, rest)),
    )
    xs, ys, speeds, headings, rates = (
        np.concatenate([a, b], axis=1) if first else b
        for a, b in zip((head.xs, head.ys, head.speeds, head.headings, head.rates), tail)
    )
    return Rollout(xs, ys, speeds, headings, rates, np.concatenate([head.queue, np.zeros((m, rest))], axis=1))


def turn_keep_out(
    x: np.ndarray,
    y: np.ndarray,
    v: np.ndarray,
    phi: np.ndarray,
    lag_state: LagState,
    sign: float | np.ndarray,
    airframe: AirframeLag,
    lim: Limits,
    dt_s: float,
) -> tuple[Rollout, np.ndarray, np.ndarray, np.ndarray]:
    """A maximum-rate turn (``sign`` +1 left, -1 right, or (M,) of them) held for ever at constant speed from each
    state: its first K steps (:meth:`AirframeLag.settle_steps`) as samples, and the disk the rest stays in, centre
    (M,) x, y and radius (M,) (module docstring)."""
    m = len(x)
    k = airframe.settle_steps(dt_s)
    command = sign * lim.turn_rate_max_rad_s
    path = lagged_rollout(
        x, y, v, phi, lag_state, np.repeat(command[:, None], k, axis=1), np.zeros((m, k)), airframe, lim, dt_s
    )
    px, py, heading, speed = path.xs[:, -1], path.ys[:, -1], path.headings[:, -1], path.speeds[:, -1]
    r = speed / lim.turn_rate_max_rad_s
    # K covers every delay, so the command is followed from step K on: the gap decays as a first-order lag, at least
    # as fast as the longer time constant says.
    rho = r * np.abs(path.rates[:, -1] - command) * airframe.longest_tau_s()
    cx, cy = px - sign * r * np.sin(heading), py + sign * r * np.cos(heading)
    return path, cx, cy, r + rho


@dataclass(frozen=True)
class LeadEnds:
    """The candidate leads flown straight from each state under the model, at their ends, (M, L) each."""

    least_m: np.ndarray
    """The least clearance of the lead's samples, every step's and the start's, each less half a step's distance."""
    xs: np.ndarray
    ys: np.ndarray
    speeds: np.ndarray
    headings: np.ndarray
    lag: LagState
    """The lag's state where each lead ends, M * L rows (row = vehicle * L + lead)."""


def lead_ends(
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
    half_step_m: np.ndarray,
    wind_m_s: tuple[np.ndarray, np.ndarray] | None = None,
) -> LeadEnds:
    """Straight flight (heading-rate command 0, speed held) under the model for each lead of ``leads`` (world steps),
    carried by the steady ``wind_m_s`` ((M,) east and north; None: calm air): where each ends and the least clearance
    of its samples, the start included (the arc of a step lies within ``half_step_m`` of one of its ends).

    The open part is flown step by step; a held lead's part on its line (:func:`held_rollout`) is a row of equally
    spaced samples on a straight line, whose least clearance :class:`HeldLine` finds without flying them."""
    leads = np.asarray(leads, dtype=np.int64)
    m, width = len(x), lag_state.pending_rad_s.shape[1]
    longest = int(leads.max(initial=0))
    held_from = airframe.held_from_steps(dt_s)
    if held_from is not None and longest > held_from and wind_m_s is not None:
        raise ValueError("a lead that holds its course is predicted for calm air only")
    open_steps = longest if held_from is None else min(longest, held_from)
    least = np.repeat(point_clearance(x[:, None], y[:, None], hz) - half_step_m[:, None], open_steps + 1, axis=1)
    xs, ys, speeds, headings = (a[:, None] for a in (x, y, v, phi))
    rates, queue = lag_state.omega_rad_s[:, None], lag_state.pending_rad_s
    if open_steps:
        straight = straight_rollout(x, y, v, phi, lag_state, open_steps, airframe, lim, dt_s)
        sx, sy = straight.xs, straight.ys
        if wind_m_s is not None:
            t = dt_s * np.arange(1, open_steps + 1)[None, :]
            sx, sy = sx + wind_m_s[0][:, None] * t, sy + wind_m_s[1][:, None] * t
        along = np.minimum.accumulate(point_clearance(sx, sy, hz) - half_step_m[:, None], axis=1)
        least[:, 1:] = np.minimum(least[:, 1:], along)
        start = (xs, ys, speeds, headings, rates)
        flown = (sx, sy, straight.speeds, straight.headings, straight.rates)
        xs, ys, speeds, headings, rates = (np.concatenate([a, b], 1) for a, b in zip(start, flown))
        queue = straight.queue
    opened = np.minimum(leads, open_steps)
    ends_least, ex, ey, ev, ep, er = (a[:, opened] for a in (least, xs, ys, speeds, headings, rates))
    pending = np.stack([queue[:, k : k + width] for k in opened], axis=1)  # (M, L, D)
    held = np.flatnonzero(leads > open_steps)
    if len(held):  # on the line through the open part's end, along its heading, at its speed
        v_line = speeds[:, -1] if open_steps else np.clip(v, lim.speed_min_m_s, lim.speed_max_m_s)
        line = HeldLine(xs[:, -1], ys[:, -1], v_line * dt_s, headings[:, -1])
        for i in held:
            steps = int(leads[i]) - open_steps
            ends_least[:, i] = np.minimum(least[:, -1], line.least_clearance(steps, hz) - half_step_m)
            ex[:, i], ey[:, i] = line.sample(np.full(m, float(steps)))
            er[:, i] = 0.0  # straight and steady on the line, nothing pending
            pending[:, i] = 0.0
    lag = LagState(er.reshape(-1), pending.reshape(m * len(leads), width))
    return LeadEnds(ends_least, ex, ey, ev, ep, lag)


@dataclass(frozen=True)
class HeldLine:
    """A held lead's line (the held part of :func:`held_rollout`, the same arithmetic): its sample k >= 1 lies at
    (x0, y0) + k step (cos phi, sin phi), (M,) each."""

    x0: np.ndarray
    y0: np.ndarray
    step_m: np.ndarray
    """v dt: the distance between samples."""
    heading: np.ndarray

    def sample(self, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Samples ``k``, (M,) or (M, K)."""
        col = (slice(None),) + (None,) * (np.ndim(k) - 1)
        along = self.step_m[col] * k
        return self.x0[col] + along * np.cos(self.heading)[col], self.y0[col] + along * np.sin(self.heading)[col]

    def least_clearance(self, steps: int, hz: Hazards) -> np.ndarray:
        """The least clearance of samples 1..``steps`` (:func:`~tssac_core.assurance.monitor.point_clearance`'s),
        (M,): from the area's edges at an end (the distance to an edge is linear along the line), from each radar
        at the sample nearest the foot of its centre's perpendicular (the squared distance is a parabola in k)."""
        m, a = len(self.x0), hz.area_m
        edge = np.full(m, np.inf)
        for k in (1.0, float(steps)):
            px, py = self.sample(np.full(m, k))
            edge = np.minimum.reduce([edge, px, a - px, py, a - py])
        dx, dy = hz.centres_m[:, :, 0] - self.x0[:, None], hz.centres_m[:, :, 1] - self.y0[:, None]
        foot = (dx * np.cos(self.heading)[:, None] + dy * np.sin(self.heading)[:, None]) / self.step_m[:, None]
        sx, sy = self.sample(np.clip(np.rint(foot), 1.0, float(steps)))
        radar = np.hypot(sx - hz.centres_m[:, :, 0], sy - hz.centres_m[:, :, 1]) - hz.radii_m
        radar = np.where(hz.radii_m > 0, radar, np.inf)
        return np.minimum(edge, radar.min(axis=1, initial=np.inf))


def lagged_backup_clearance(
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
) -> np.ndarray:
    """Clearance of every constant-speed backup flown for ever under the model from each state, less the airframe's
    residual, (M, L * 2) (candidate lead * 2 + turn; turn 0 left, 1 right, as the monitor's first two ``TURNS``).

    A backup flies straight (heading-rate command 0, speed held) for its lead of ``leads`` world steps, then its
    maximum-rate turn for ever: the lead's samples, the turn's K samples (less v_max dt / 2 each) and the disk the
    rest stays in (module docstring)."""
    m, n_leads = len(x), len(leads)
    half_step = lim.speed_max_m_s * dt_s / 2
    ends = lead_ends(x, y, v, phi, lag_state, hz, airframe, lim, dt_s, leads, half_step)
    rows, both = np.repeat(np.arange(m), n_leads * 2), np.arange(m * n_leads).repeat(2)
    ex, ey, ev, ep = (a.reshape(-1)[both] for a in (ends.xs, ends.ys, ends.speeds, ends.headings))
    sign = np.tile([1.0, -1.0], m * n_leads)
    r_hz, r_air, r_lim = hz.select(rows), airframe.select(rows), lim.select(rows)
    path, cx, cy, radius = turn_keep_out(ex, ey, ev, ep, ends.lag.select(both), sign, r_air, r_lim, dt_s)
    samples = point_clearance(path.xs, path.ys, r_hz).min(axis=1) - half_step[rows]
    disk = circle_clearance(cx, cy, radius, r_hz)
    out = np.minimum.reduce([ends.least_m.reshape(-1)[both], samples, disk]).reshape(m, n_leads, 2)
    return (out - airframe.lead_residual_m(leads, dt_s)[:, :, None]).reshape(m, n_leads * 2)
