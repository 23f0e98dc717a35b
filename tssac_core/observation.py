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


def build_observation(
    role_index: int,
    mode: ObservationMode,
    c: WorldConstants,
    x_m: np.ndarray,
    y_m: np.ndarray,
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

    Vehicle arrays are (N,) for the observing UAV; ``sam_m``/``target_m`` (N, 2); ``radar_m`` (N, K, 2);
    ``radar_r_m`` (N, K); flags (N,); ``route_dir`` (N, 2) unit vectors in the world frame (route mode
    only). This is the only place observations are made.
    """
    j = role_index
    area = c.area_m
    low, high = _BOUNDS[mode]
    speed = (v_m_s - c.speed_min_m_s[j]) / (c.speed_max_m_s[j] - c.speed_min_m_s[j])
    l_m = np.hypot(target_m[:, 0] - x_m, target_m[:, 1] - y_m)
    if mode is ObservationMode.PAPER:
        obs = np.stack([x_m / area, y_m / area, speed, phi_rad / np.pi, l_m / area], axis=1)
        return np.minimum(np.maximum(obs, low), high).astype(np.float32)

    n = x_m.shape[0]
    out = np.empty((n, mode.size))
    cos_phi, sin_phi = np.cos(phi_rad), np.sin(phi_rad)
    out[:, 0] = x_m / area
    out[:, 1] = y_m / area
    out[:, 2] = speed
    out[:, 3] = cos_phi
    out[:, 4] = sin_phi
    out[:, 5] = l_m / area

    # The SAM and the radars in one pass: ranges and bearings relative to the heading, (N, 1 + K).
    points = np.concatenate([sam_m[:, None, :], radar_m], axis=1)
    dx = points[:, :, 0] - x_m[:, None]
    dy = points[:, :, 1] - y_m[:, None]
    d = np.hypot(dx, dy)
    inv = 1.0 / np.maximum(d, 1e-9)  # on the point itself the bearing is (0, 0)
    ux, uy = dx * inv, dy * inv
    c_phi, s_phi = cos_phi[:, None], sin_phi[:, None]
    rel_cos = ux * c_phi + uy * s_phi  # the unit vector rotated by -phi
    rel_sin = uy * c_phi - ux * s_phi

    d_sam = d[:, 0]
    out[:, 6] = rel_cos[:, 0]
    out[:, 7] = rel_sin[:, 0]
    out[:, 8] = d_sam / area
    out[:, 9] = (d_sam - c.zone_outer_m[j]) / LOCAL_SCALE_M
    out[:, 10] = (d_sam - c.zone_inner_m[j]) / LOCAL_SCALE_M

    # Radars, nearest edge first; padding slots (radius 0) read as far away, dead ahead.
    feats = np.stack([(d[:, 1:] - radar_r_m) / LOCAL_SCALE_M, rel_cos[:, 1:], rel_sin[:, 1:]], axis=2)  # (N, K, 3)
    padding = radar_r_m <= 0
    if padding.any():
        feats = np.where(padding[:, :, None], _FAR_RADAR, feats)
    k = feats.shape[1]
    if k < N_RADAR_FEATURES:
        feats = np.concatenate([feats, np.broadcast_to(_FAR_RADAR, (n, N_RADAR_FEATURES - k, 3))], axis=1)
    order = np.argsort(feats[:, :, 0], axis=1)[:, :N_RADAR_FEATURES]
    out[:, 11 : 11 + 3 * N_RADAR_FEATURES] = np.take_along_axis(feats, order[:, :, None], axis=1).reshape(n, -1)
    out[:, 20] = radar_on
    out[:, 21] = identified
    if mode is ObservationMode.ROUTE:
        if route_dir is None:
            raise ValueError("the route observation needs the route direction (observe(..., routes=RouteMap()))")
        out[:, 22] = route_dir[:, 0] * cos_phi + route_dir[:, 1] * sin_phi
        out[:, 23] = route_dir[:, 1] * cos_phi - route_dir[:, 0] * sin_phi
    return np.minimum(np.maximum(out, low), high).astype(np.float32)


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
        world.x_m[:, j],
        world.y_m[:, j],
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
