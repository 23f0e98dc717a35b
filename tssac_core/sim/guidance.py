"""A rule-based guidance controller: the reference every learned policy is measured against.

Per UAV, each step (batched over worlds and vehicles):

1. Zone course: a vector field that converges on a counter-clockwise orbit of the SAM at the middle
   of the role's zone (decoy 18.5 km, detect 11.5 km, strike 6 km):
   ``chi = psi + pi/2 + atan((D - R_orbit) / W)``, psi the bearing from the SAM to the UAV. Far out it
   points at the SAM; on the orbit it is tangent; inside it points outwards.
2. Route around the hazards: outside the SAM's detection disk (which layouts keep free of radars) the
   UAV follows a navigation function instead: the geodesic distance to that disk on a 1 km grid, with
   the radars inflated by a margin as obstacles (a wavefront planner, computed once per layout). Its
   descent direction has no local minima, so clusters of radars are flown around, through the gap
   if there is one. Near the disk the two courses blend.
3. Last-moment safety: a course that points into a radar (inflated by a small margin) within a short
   look-ahead is bent to that radar's nearer tangent.
4. Heading-rate command proportional to the course error, saturated at the vehicle's limit; speed held
   at a cruise speed (full speed by default) with the acceleration command.

The controller uses what the extended observation gives a policy (its own state and the layout), so
it is a fair reference; it knows nothing of its teammates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tssac_core.sim.routes import FieldCache, cell_centres, field_gradient, radar_depth, sam_disk, wavefronts
from tssac_core.sim.world import wrap_angle
from tssac_core.sim.world_state import WorldState


@dataclass(frozen=True)
class GuidanceConfig:
    """Gains and margins of the guidance controller."""

    orbit_fraction: tuple[float, float, float] = (0.5, 0.5, 0.6)
    """Orbit radius within each zone: inner + fraction * (outer - inner) (strike: fraction of R1)."""
    transition_m: float = 2500.0
    """W: width of the vector field's transition from approach to orbit."""
    grid_m: float = 1000.0
    """Cell size of the navigation function."""
    plan_margin_m: float = 3000.0
    """Radars are planned around as disks of radius + this margin."""
    blend_m: float = 5000.0
    """Beyond R4 + blend the route course is flown, inside R4 the zone course, linear in between."""
    safety_margin_m: float = 1000.0
    """Last-moment avoidance: disks of radius + this margin ..."""
    safety_lookahead_m: float = 3000.0
    """... whose edge is nearer than this."""
    heading_gain_1_s: float = 0.6
    """Turn-rate command per radian of course error."""
    speed_gain_1_s: float = 0.2
    """Acceleration command per m/s of speed error."""
    cruise_fraction: float = 1.0
    """Cruise speed: v_min + fraction * (v_max - v_min) (full speed: long detours must fit the episode cap)."""


def orbit_radii_m(state: WorldState, cfg: GuidanceConfig) -> np.ndarray:
    c = state.c
    inner = np.array([c.r3_m, c.r1_m, 0.0])
    outer = np.array([c.r4_m, c.r2_m, c.r1_m])
    return inner + np.asarray(cfg.orbit_fraction) * (outer - inner)


class Guidance:
    """The controller for every vehicle of every world of a :class:`WorldState`; caches one plan per layout."""

    def __init__(self, cfg: GuidanceConfig = GuidanceConfig()) -> None:
        self.cfg = cfg
        self._plans = FieldCache(self._plan)

    def _plan(self, state: WorldState, worlds: np.ndarray) -> np.ndarray:
        return navigation_functions(state, worlds, self.cfg)

    def actions(self, state: WorldState) -> np.ndarray:
        """Actions (N, 3, 2) in [-1, 1] for every vehicle of every state."""
        cfg, c = self.cfg, state.c
        x, y = state.x_m, state.y_m
        dx, dy = x - state.sam_m[:, 0:1], y - state.sam_m[:, 1:2]
        d_sam = np.hypot(dx, dy)
        zone_course = np.arctan2(dy, dx) + np.pi / 2 + np.arctan((d_sam - orbit_radii_m(state, cfg)) / cfg.transition_m)

        gx, gy = self._route_gradient(state)
        route_course = np.arctan2(-gy, -gx)
        w = np.clip((d_sam - c.r4_m) / cfg.blend_m, 0.0, 1.0)
        course = zone_course + w * wrap_angle(route_course - zone_course)

        course = self._safety(state, course)
        err = wrap_angle(course - state.phi_rad)
        omega_cmd = cfg.heading_gain_1_s * err / c.turn_rate_max_rad_s
        cruise = c.speed_min_m_s + cfg.cruise_fraction * (c.speed_max_m_s - c.speed_min_m_s)
        accel_cmd = cfg.speed_gain_1_s * (cruise - state.v_m_s) / c.accel_max_m_s2
        return np.clip(np.stack([omega_cmd, accel_cmd], axis=-1), -1.0, 1.0)

    def _route_gradient(self, state: WorldState) -> tuple[np.ndarray, np.ndarray]:
        """Gradient of the navigation function at every vehicle, (N, 3) each."""
        return field_gradient(self._plans.fields(state), self.cfg.grid_m, state.x_m, state.y_m)

    def _safety(self, state: WorldState, course: np.ndarray) -> np.ndarray:
        cfg = self.cfg
        rx = state.radar_m[:, None, :, 0] - state.x_m[:, :, None]
        ry = state.radar_m[:, None, :, 1] - state.y_m[:, :, None]
        rd = np.hypot(rx, ry)
        real = state.radar_r_m[:, None, :] > 0
        rb = state.radar_r_m[:, None, :] + cfg.safety_margin_m
        bearing = np.arctan2(ry, rx)
        half = np.arcsin(np.clip(rb / np.maximum(rd, 1.0), 0.0, 1.0))
        half = np.where(rd < rb, np.pi / 2 + np.clip((rb - rd) / rb, 0, 1) * np.pi / 4, half)
        near = real & (rd - rb < cfg.safety_lookahead_m)
        off = wrap_angle(course[..., None] - bearing)
        blocked = near & (np.abs(off) < half)
        # The nearest blocking radar decides (margins are small, so radars rarely block together).
        key = np.where(blocked, rd - rb, np.inf)
        k = np.argmin(key, axis=2)[..., None]
        any_blocked = np.isfinite(np.min(key, axis=2))
        b = np.take_along_axis(bearing, k, axis=2)[..., 0]
        h = np.take_along_axis(half, k, axis=2)[..., 0]
        o = np.take_along_axis(off, k, axis=2)[..., 0]
        return np.where(any_blocked, b + np.where(o >= 0, 1.0, -1.0) * h, course)


def navigation_functions(state: WorldState, worlds: np.ndarray, cfg: GuidanceConfig) -> np.ndarray:
    """Geodesic distance (in cells) from every cell to the SAM's detection disk, around inflated radars, of each
    of the given worlds, (K, size, size).

    8-neighbour wavefront (:func:`tssac_core.sim.routes.wavefronts`); blocked cells get the largest free
    value plus their depth into the obstacle, so the gradient also points out of a disk.
    """
    cx, cy = cell_centres(state.c.area_m, cfg.grid_m)
    goal = np.stack([sam_disk(state, int(k), cx, cy) for k in worlds])
    depth = np.stack([np.maximum(radar_depth(state, int(k), cx, cy, cfg.plan_margin_m), 0.0) for k in worlds])
    free = depth <= 0
    dist = wavefronts(goal, np.where(free | goal, 1.0, np.inf))
    reachable = np.isfinite(dist)
    # Per world: the largest reachable value (0 when none is).
    reachable_max = np.where(reachable, dist, 0.0).max(axis=(1, 2), initial=0.0)[:, None, None]
    # Unreachable free cells (boxed in) and obstacle cells: uphill away from the obstacles.
    fallback = reachable_max + 1.0 + depth / cfg.grid_m
    return np.where(reachable, dist, fallback).astype(np.float32)
