"""The observation: one function, used by training, evaluation and the MAVLink bridge alike.

Two modes (DESIGN.md section 2):

``paper`` (eq. 7), 5 values: ``[x, y, v, phi, l]``

    ==  =====================  ===========================================  =========
    i   name                   definition                                   range
    ==  =====================  ===========================================  =========
    0   x                      x / area                                     [0, 1]
    1   y                      y / area                                     [0, 1]
    2   v                      (v - v_min) / (v_max - v_min)                [0, 1]
    3   phi                    heading / pi                                 [-1, 1]
    4   l                      distance to the target / area                [0, 1.5]
    ==  =====================  ===========================================  =========

``extended`` (default), 22 values: eq. 7 (with the heading as cos/sin, which has no jump at +-pi),
then what a UAV needs to fly around hazards whose positions change from layout to layout, and the
mission flags it can know in flight. The layout is the same for all three roles, so that parameters
transfer between them; only the zone edges differ (each role's own zone).

    ======  ======================  =============================================================  =======
    i       name                    definition                                                     range
    ======  ======================  =============================================================  =======
    0-1     x, y                    position / area                                                [0, 1]
    2       v                       (v - v_min) / (v_max - v_min)                                  [0, 1]
    3-4     cos phi, sin phi        heading                                                        [-1, 1]
    5       l                       distance to the target / area                                  [0, 1.5]
    6-7     sam cos, sin            bearing of the SAM relative to the heading                     [-1, 1]
    8       sam range               D / area                                                       [0, 1.5]
    9       zone outer              (D - outer edge of own zone) / LOCAL_SCALE, clipped            [-1, 1]
    10      zone inner              (D - inner edge of own zone) / LOCAL_SCALE, clipped            [-1, 1]
    11-19   radars (x3)             nearest first: (range - radius) / LOCAL_SCALE clipped,         [-1, 1]
                                    cos and sin of the bearing relative to the heading
    20      radar on                the SAM radar is on (the decoy holds its ring)                 {0, 1}
    21      identified              the target has been identified                                 {0, 1}
    ======  ======================  =============================================================  =======

A layout with fewer radars pads with "far away" (range 1, bearing dead ahead).

``route`` (the training default), 24 values: ``extended`` plus where the way to the SAM's detection
disk around the radars starts, relative to the heading — the descent direction of the route field
that the reward's approach term measures (:class:`tssac_core.sim.routes.RouteMap`; straight at the SAM
inside the disk). It is a function of the layout the other entries already describe, precomputed
the way a mission planner would: which way round a cluster of radars is shorter is a global
question that three nearest-radar entries only answer after much learning.

    ======  ======================  =============================================================  =======
    22-23   route cos, sin          direction of the way around the radars relative to the heading  [-1, 1]
    ======  ======================  =============================================================  =======
"""

from __future__ import annotations

import enum
import functools

import numpy as np

from tssac_core.sim.routes import RouteMap
from tssac_core.sim.world import WorldConstants, cached_constant, constant_operand
from tssac_core.sim.world_state import WorldState

LOCAL_SCALE_M = 20_000.0
"""Scale of the local (zone and hazard) ranges: the SAM's detection range R4."""
N_RADAR_FEATURES = 3
EXTENDED_SIZE = 11 + 3 * N_RADAR_FEATURES + 2
ROUTE_SIZE = EXTENDED_SIZE + 2
PAPER_SIZE = 5


class ObservationMode(enum.StrEnum):
    """Which observation a policy sees (a str, so it reads and compares as its name in config files)."""

    PAPER = "paper"
    EXTENDED = "extended"
    ROUTE = "route"

    @property
    def size(self) -> int:
        return {
            ObservationMode.PAPER: PAPER_SIZE,
            ObservationMode.EXTENDED: EXTENDED_SIZE,
            ObservationMode.ROUTE: ROUTE_SIZE,
        }[self]


def observation_bounds(mode: ObservationMode) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of every observation entry (the gymnasium Box); copies, free to modify."""
    low, high = _BOUNDS[mode]
    return low.copy(), high.copy()


def _bounds(mode: ObservationMode) -> tuple[np.ndarray, np.ndarray]:
    if mode is ObservationMode.PAPER:
        low = np.array([0, 0, 0, -1, 0], dtype=np.float32)
        high = np.array([1, 1, 1, 1, 1.5], dtype=np.float32)
        return low, high
    low = np.full(mode.size, -1.0, dtype=np.float32)
    high = np.ones(mode.size, dtype=np.float32)
    low[[0, 1, 2, 5, 8, 20, 21]] = 0.0
    high[[5, 8]] = 1.5
    return low, high


_BOUNDS = {mode: _bounds(mode) for mode in ObservationMode}


def build_observation(
    role_index: int,
    mode: ObservationMode,
    c: WorldConstants,
    xy_m: np.ndarray,
    v_m_s: np.ndarray,
    phi_rad: np.ndarray,
    points_xy_m: np.ndarray,
    radar_r_m: np.ndarray,
    unused_radar_slots: bool,
    radar_on: np.ndarray,
    identified: np.ndarray,
    route_dir: np.ndarray | None = None,
) -> np.ndarray:
    """Observations of one role in N worlds, (N, mode.size) float32.

    Vehicle arrays are the observing UAV's: position ``xy_m`` (2, N), x over y (as ``WorldState.xy_m``), the
    others (N,); ``points_xy_m`` (2, N, 2 + K), x over y: the target, the SAM and the radar slots (as
    ``WorldState.points_xy_m``); ``radar_r_m`` (N, K); ``unused_radar_slots``: some radius is 0 (a slot no
    radar fills); flags (N,); ``route_dir`` (N, 2) unit vectors in the world frame (route mode only).
    This is the only place observations are made.

    Speed: the entries are computed feature-major, one contiguous (N,) row per entry, and transposed once
    at the end: at N = 1 numpy's fast path wants same-shape contiguous operands (see :class:`World`), which
    rows are and columns of an (N, size) array are not.
    """
    if mode is ObservationMode.PAPER:
        return _paper_observation(role_index, c, xy_m[0], xy_m[1], v_m_s, phi_rad, points_xy_m[:, :, 0])
    j = role_index
    area = cached_constant(c.area_m)
    n = xy_m.shape[1]
    out = np.empty((ROUTE_SIZE if mode is ObservationMode.ROUTE else EXTENDED_SIZE, n))
    xy_m = np.ascontiguousarray(xy_m)  # (a vehicle's x over y is a strided view: a copy is cheaper than its slow path)
    np.divide(xy_m, area, out=out[0:2])
    _speed(v_m_s, c, j, out=out[2])
    np.cos(phi_rad, out=out[3])
    np.sin(phi_rad, out=out[4])

    # The target, the SAM and the radars in one pass: ranges and bearings relative to the heading, (N, P = 2 + K).
    delta = points_xy_m - xy_m[:, :, None]  # (2, N, P), C-ordered as the points: delta[0], delta[1] contiguous
    d = np.hypot(delta[0], delta[1])
    inv = np.maximum(d, _TINY)
    np.divide(_ONE, inv, out=inv)  # on the point itself the bearing is (0, 0)
    for component in delta:  # unit vectors to the points
        component *= inv
    # Per point, (range to the edge, bearing cos, bearing sin), (3, N, P); the radars' columns are their features.
    feats = np.empty((3, *d.shape))
    _relative(delta, _heading(out[3], out[4], d.shape), out=feats[1:])

    np.divide(d[:, 0], area, out=out[5])  # l: distance to the target
    d_sam = d[:, 1]
    out[6:8] = feats[1:, :, 1]
    np.divide(d_sam, area, out=out[8])
    np.subtract(d_sam, cached_constant(float(c.zone_outer_m[j])), out=out[9])
    np.subtract(d_sam, cached_constant(float(c.zone_inner_m[j])), out=out[10])
    out[9:11] /= _LOCAL_SCALE
    radar_feats = feats[:, :, 2:]
    edge = np.subtract(d[:, 2:], radar_r_m)
    edge /= _LOCAL_SCALE
    radar_feats[0] = edge
    _nearest_radars(radar_feats, radar_r_m, unused_radar_slots, out=out[11 : 11 + 3 * N_RADAR_FEATURES])
    out[20] = radar_on
    out[21] = identified
    if mode is ObservationMode.ROUTE:
        if route_dir is None:
            raise ValueError("the route observation needs the route direction (observe(..., routes=RouteMap()))")
        _relative(route_dir.T, _heading(out[3], out[4], (n,)), out=out[22:24])
    return _clip_to_bounds(out, mode)


def _paper_observation(
    j: int,
    c: WorldConstants,
    x_m: np.ndarray,
    y_m: np.ndarray,
    v_m_s: np.ndarray,
    phi_rad: np.ndarray,
    target_xy_m: np.ndarray,
) -> np.ndarray:
    """Eq. 7: [x, y, v, phi, l] scaled to about [0, 1]; ``target_xy_m`` (2, N)."""
    area = c.area_m
    speed = _speed(v_m_s, c, j)
    l_m = np.hypot(target_xy_m[0] - x_m, target_xy_m[1] - y_m)
    obs = np.stack([x_m / area, y_m / area, speed, phi_rad / np.pi, l_m / area])
    return _clip_to_bounds(obs, ObservationMode.PAPER)


def _speed(v_m_s: np.ndarray, c: WorldConstants, j: int, out: np.ndarray | None = None) -> np.ndarray:
    """(v - v_min) / (v_max - v_min) of role j."""
    # Not in place: an in-place update of a one-element row (N = 1) takes numpy's slow path. The limits as
    # cached 0-d arrays: the same floats, without a conversion per call.
    v_min, v_max = float(c.speed_min_m_s[j]), float(c.speed_max_m_s[j])
    return np.divide(v_m_s - cached_constant(v_min), cached_constant(v_max - v_min), out=out)


def _heading(cos_phi: np.ndarray, sin_phi: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """(sin, cos, sin) of the heading, each broadcast from (N,) to ``shape`` (N, ...), stacked (3, N, ...).

    Stacked so that [1:] is (cos, sin) and [:2] is (sin, cos): both are contiguous views for :func:`_relative`.
    """
    heading = np.empty((3, *shape))
    expand = (slice(None),) + (None,) * (len(shape) - 1)
    heading[0] = sin_phi[expand]
    heading[1] = cos_phi[expand]
    heading[2] = heading[0]
    return heading


def _relative(u: np.ndarray, heading: np.ndarray, out: np.ndarray) -> np.ndarray:
    """Unit vectors ``u`` (2, N, ...), x over y, rotated by -phi into ``out`` (2, N, ...): (cos, sin) of their
    bearing relative to the heading; ``heading`` is :func:`_heading`'s (sin, cos, sin) of the same shape.

    rel_cos = ux cos + uy sin, rel_sin = uy cos - ux sin, as two products with the heading (straight and
    swapped) and one sum and one difference, every operand of one shape.
    """
    straight = u * heading[1:]  # (ux cos, uy sin)
    swapped = u * heading[:2]  # (ux sin, uy cos)
    np.add(straight[0], straight[1], out=out[0])
    np.subtract(swapped[1], swapped[0], out=out[1])
    return out


def _nearest_radars(feats: np.ndarray, radius_m: np.ndarray, unused_slots: bool, out: np.ndarray) -> None:
    """The N_RADAR_FEATURES nearest radar edges into ``out`` (3 * N_RADAR_FEATURES, N), radar by radar, from
    every radar slot's features (3, N, K): (range - radius) / LOCAL_SCALE, cos and sin of the bearing.

    Padding slots (radius 0) and missing ones read as far away, dead ahead.
    """
    n, k = radius_m.shape
    if k < N_RADAR_FEATURES:
        far = np.broadcast_to(_FAR_RADAR[:, None, None], (3, n, N_RADAR_FEATURES - k))
        feats = np.concatenate([feats, far], axis=2)
    if unused_slots:
        padding = radius_m <= 0
        feats = feats.copy()
        feats[:, :, :k] = np.where(padding, _FAR_RADAR[:, None, None], feats[:, :, :k])
    order = feats[0].argsort(axis=1)[:, :N_RADAR_FEATURES]
    order += _row_starts(n, feats.shape[2])  # flat indices into each feature's (N * K) values
    nearest = feats.reshape(3, -1).take(order, axis=1)  # (3, N, N_RADAR_FEATURES)
    out.reshape(N_RADAR_FEATURES, 3, n)[...] = nearest.transpose(2, 0, 1)


@functools.lru_cache(maxsize=16)
def _row_starts(n: int, k: int) -> np.ndarray:
    """Where each row starts in an (N, K) array flattened, (N, N_RADAR_FEATURES), for picking per-row columns."""
    return np.ascontiguousarray(np.broadcast_to(np.arange(n)[:, None] * k, (n, N_RADAR_FEATURES)))


@functools.lru_cache(maxsize=16)
def _bounds_of(mode: ObservationMode, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The bounds of ``mode`` as (size, N) arrays: same-shape operands for the clip."""
    low, high = (
        np.ascontiguousarray(np.broadcast_to(b[:, None], (b.size, n)), dtype=np.float64) for b in _BOUNDS[mode]
    )
    return low, high


def _clip_to_bounds(obs: np.ndarray, mode: ObservationMode) -> np.ndarray:
    """Clip feature-major (size, N) entries of ``mode`` to its bounds; the observations (N, size) float32."""
    low, high = _bounds_of(mode, obs.shape[1])
    np.maximum(obs, low, out=obs)
    np.minimum(obs, high, out=obs)
    return obs.T.astype(np.float32, order="C")


_ONE, _TINY, _LOCAL_SCALE = constant_operand(1.0), constant_operand(1e-9), constant_operand(LOCAL_SCALE_M)

_FAR_RADAR = np.array([1e9, 1.0, 0.0])
"""Features of a radar slot a layout does not use: sorted last, range clipped to 1, bearing dead ahead."""


def observe(state: WorldState, role_index: int, mode: ObservationMode, routes: RouteMap | None = None) -> np.ndarray:
    """Observations of one role in every world of ``state``, (N, mode.size) float32.

    ``state``: a batched World's :func:`~tssac_core.sim.world_state.snapshot`, or a companion's estimate.
    ``routes``: the route fields of the route mode (one RouteMap per World you observe: it caches a
    field per layout); ignored by the other modes.
    """
    j = role_index
    return build_observation(
        j,
        mode,
        state.c,
        state.xy_m[:, :, j],
        state.v_m_s[:, j],
        state.phi_rad[:, j],
        state.points_xy_m,
        state.radar_r_m,
        state.has_unused_radar_slots,
        state.radar_on,
        state.identified,
        routes.direction(state, j) if mode is ObservationMode.ROUTE and routes is not None else None,
    )
