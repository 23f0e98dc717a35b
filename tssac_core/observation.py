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
that the reward's approach term measures (:class:`tssac_core.routes.RouteMap`; straight at the SAM
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

from tssac_core.routes import RouteMap
from tssac_core.world import World, WorldConstants

LOCAL_SCALE_M = 20_000.0
"""Scale of the local (zone and hazard) ranges: the SAM's detection range R4."""
N_RADAR_FEATURES = 3
EXTENDED_SIZE = 11 + 3 * N_RADAR_FEATURES + 2
ROUTE_SIZE = EXTENDED_SIZE + 2
PAPER_SIZE = 5


class ObservationMode(enum.Enum):
    PAPER = "paper"
    EXTENDED = "extended"
    ROUTE = "route"

    @property
    def size(self) -> int:
        return {ObservationMode.PAPER: PAPER_SIZE, ObservationMode.EXTENDED: EXTENDED_SIZE, ObservationMode.ROUTE: ROUTE_SIZE}[self]


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
_SIZES = {mode: mode.size for mode in ObservationMode}


def build_observation(
    role_index: int,
    mode: ObservationMode,
    c: WorldConstants,
    xy_m: np.ndarray,
    v_m_s: np.ndarray,
    phi_rad: np.ndarray,
    sam_m: np.ndarray,
    target_m: np.ndarray,
    radar_m: np.ndarray,
    radar_r_m: np.ndarray,
    radar_on: np.ndarray,
    identified: np.ndarray,
    route_dir: np.ndarray | None = None,
) -> np.ndarray:
    """Observations of one role in N worlds, (N, mode.size) float32.

    Vehicle arrays are the observing UAV's: position ``xy_m`` (N, 2), the others (N,); ``sam_m``/``target_m`` (N, 2); ``radar_m`` (N, K, 2);
    ``radar_r_m`` (N, K); flags (N,); ``route_dir`` (N, 2) unit vectors in the world frame (route mode
    only). This is the only place observations are made.
    """
    if mode is ObservationMode.PAPER:
        return _paper_observation(role_index, c, xy_m[:, 0], xy_m[:, 1], v_m_s, phi_rad, target_m)
    j = role_index
    area = c.area_m
    n = xy_m.shape[0]
    out = np.empty((n, _SIZES[mode]))
    np.divide(xy_m, area, out=out[:, 0:2])
    _speed(v_m_s, c, j, out=out[:, 2])
    heading = out[:, 3:5]  # cos phi, sin phi
    np.cos(phi_rad, out=out[:, 3])
    np.sin(phi_rad, out=out[:, 4])

    # The target, the SAM and the radars in one pass: ranges and bearings relative to the heading, (N, 2 + K).
    points = np.concatenate([target_m[:, None, :], sam_m[:, None, :], radar_m], axis=1)
    delta = points - xy_m[:, None, :]
    d = np.hypot(delta[:, :, 0], delta[:, :, 1])
    inv = np.maximum(d, 1e-9)
    np.divide(1.0, inv, out=inv)  # on the point itself the bearing is (0, 0)
    delta *= inv[:, :, None]  # unit vectors to the points
    # Per point: (range to the edge, bearing cos, bearing sin); the radars' rows are their features.
    points_feats = np.empty((n, points.shape[1], 3))
    _relative(delta, heading, out=points_feats[:, :, 1:])

    np.divide(d[:, 0], area, out=out[:, 5])  # l: distance to the target
    d_sam = d[:, 1]
    out[:, 6:8] = points_feats[:, 1, 1:]
    np.divide(d_sam, area, out=out[:, 8])
    np.subtract(d_sam, c.zone_outer_m[j], out=out[:, 9])
    np.subtract(d_sam, c.zone_inner_m[j], out=out[:, 10])
    out[:, 9:11] /= LOCAL_SCALE_M
    radar_feats = points_feats[:, 2:]
    np.subtract(d[:, 2:], radar_r_m, out=radar_feats[:, :, 0])
    radar_feats[:, :, 0] /= LOCAL_SCALE_M
    out[:, 11 : 11 + 3 * N_RADAR_FEATURES] = _nearest_radars(radar_feats, radar_r_m)
    out[:, 20] = radar_on
    out[:, 21] = identified
    if mode is ObservationMode.ROUTE:
        if route_dir is None:
            raise ValueError("the route observation needs the route direction (observe(..., routes=RouteMap()))")
        out[:, 22:24] = _relative(route_dir, heading)
    return _clip_to_bounds(out, mode)


def _paper_observation(j: int, c: WorldConstants, x_m: np.ndarray, y_m: np.ndarray, v_m_s: np.ndarray,
                       phi_rad: np.ndarray, target_m: np.ndarray) -> np.ndarray:
    """Eq. 7: [x, y, v, phi, l] scaled to about [0, 1]."""
    area = c.area_m
    speed = _speed(v_m_s, c, j)
    l_m = np.hypot(target_m[:, 0] - x_m, target_m[:, 1] - y_m)
    obs = np.stack([x_m / area, y_m / area, speed, phi_rad / np.pi, l_m / area], axis=1)
    return _clip_to_bounds(obs, ObservationMode.PAPER)


def _speed(v_m_s: np.ndarray, c: WorldConstants, j: int, out: np.ndarray | None = None) -> np.ndarray:
    """(v - v_min) / (v_max - v_min) of role j."""
    speed = np.subtract(v_m_s, c.speed_min_m_s[j], out=out)
    speed /= c.speed_max_m_s[j] - c.speed_min_m_s[j]
    return speed


def _relative(u: np.ndarray, heading: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Unit vectors ``u`` (N, ..., 2) rotated by -phi: (cos, sin) of their bearing relative to the heading.

    ``heading`` (N, 2) is (cos phi, sin phi). rel_cos = ux cos + uy sin, rel_sin = uy cos - ux sin, as two
    products with the heading (straight and swapped) and one sum and one difference.
    """
    shape = (heading.shape[0],) + (1,) * (u.ndim - 2) + (2,)
    straight = u * heading.reshape(shape)  # (ux cos, uy sin)
    swapped = u * heading[:, ::-1].reshape(shape)  # (ux sin, uy cos)
    rel = np.empty(u.shape) if out is None else out
    np.add(straight[..., 0], straight[..., 1], out=rel[..., 0])
    np.subtract(swapped[..., 1], swapped[..., 0], out=rel[..., 1])
    return rel


def _nearest_radars(feats: np.ndarray, radius_m: np.ndarray) -> np.ndarray:
    """The N_RADAR_FEATURES nearest radar edges, (N, 3 * N_RADAR_FEATURES), from every radar slot's
    features (N, K, 3): (range - radius) / LOCAL_SCALE, cos and sin of the bearing.

    Padding slots (radius 0) and missing ones read as far away, dead ahead.
    """
    n, k = radius_m.shape
    if k < N_RADAR_FEATURES:
        feats = np.concatenate([feats, np.broadcast_to(_FAR_RADAR, (n, N_RADAR_FEATURES - k, 3))], axis=1)
    padding = radius_m <= 0
    if padding.any():
        feats = feats.copy()
        feats[:, :k] = np.where(padding[:, :, None], _FAR_RADAR, feats[:, :k])
    order = np.argsort(feats[:, :, 0], axis=1)[:, :N_RADAR_FEATURES]
    return feats[_rows(n), order].reshape(n, -1)


@functools.lru_cache(maxsize=16)
def _rows(n: int) -> np.ndarray:
    """Row indices (N, 1) for picking per-row columns by fancy indexing."""
    return np.arange(n)[:, None]



def _clip_to_bounds(obs: np.ndarray, mode: ObservationMode) -> np.ndarray:
    low, high = _BOUNDS[mode]
    np.maximum(obs, low, out=obs)
    np.minimum(obs, high, out=obs)
    return obs.astype(np.float32)


_FAR_RADAR = np.array([1e9, 1.0, 0.0])
"""Features of a radar slot a layout does not use: sorted last, range clipped to 1, bearing dead ahead."""


def observe(world: World, role_index: int, mode: ObservationMode, routes: RouteMap | None = None) -> np.ndarray:
    """Observations of one role in every world of ``world``, (N, mode.size) float32.

    ``routes``: the route fields of the route mode (one RouteMap per World you observe: it caches a
    field per layout); ignored by the other modes.
    """
    j = role_index
    return build_observation(
        j,
        mode,
        world.c,
        world.xy_m[:, :, j].T,
        world.v_m_s[:, j],
        world.phi_rad[:, j],
        world.sam_m,
        world.target_m,
        world.radar_m,
        world.radar_r_m,
        world.radar_on,
        world.identified,
        routes.direction(world, j) if mode is ObservationMode.ROUTE and routes is not None else None,
    )
