"""What the pilots read of a world: a small snapshot of N worlds' state, without their physics.

The observation (:mod:`tssac_core.sim.observation`), the guidance controller, the adversaries and the route
fields read positions, headings, speeds, the layout and the mission flags, nothing else. A batched
:class:`~tssac_core.sim.world.World` hands them :func:`snapshot` (views of its arrays: no copies, valid until the
world next steps or resets); a companion computer builds one world's snapshot from its Kalman filter and its
datalink (:func:`initial_state`, then :meth:`WorldState.with_vehicle` each tick), without a World of its own.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tssac_core.sim.scenario import Layout, Scenario
from tssac_core.sim.world import World, WorldConstants, wrap_angle


class WorldState(NamedTuple):
    """N worlds of three UAVs as the pilots see them (shapes as :class:`World`'s arrays; read, never write).

    A NamedTuple: made every step of the batched world, it costs a tuple, not a dataclass's attribute writes.
    """

    c: WorldConstants
    xy_m: np.ndarray
    """Positions, (2, N, 3): x over y."""
    v_m_s: np.ndarray
    """Speeds, (N, 3)."""
    phi_rad: np.ndarray
    """Headings, (N, 3), in [-pi, pi)."""
    sam_m: np.ndarray
    """The SAM, (N, 2)."""
    target_m: np.ndarray
    """The target, (N, 2)."""
    radar_m: np.ndarray
    """Radar centres, (N, K, 2) (unused slots far outside the area)."""
    radar_r_m: np.ndarray
    """Radar radii, (N, K) (unused slots 0)."""
    points_xy_m: np.ndarray
    """The target, the SAM, then the radar slots, (2, N, 2 + K), x over y (:attr:`World.points_xy_m`)."""
    sam_xy_m: np.ndarray
    """The SAM per vehicle, (2, N, 3), x over y (:attr:`World.sam_xy_m`)."""
    has_unused_radar_slots: bool
    """Some radius is 0 (a slot no radar fills)."""
    radar_on: np.ndarray
    """The SAM radar is on, (N,) bool."""
    identified: np.ndarray
    """The target has been identified, (N,) bool."""
    steps: np.ndarray
    """Steps since each world's mission started, (N,) int64."""
    layout_token: object
    """The same object while the layout arrays stay the same (caches of per-layout work compare it)."""

    @property
    def n(self) -> int:
        return self.xy_m.shape[1]

    @property
    def x_m(self) -> np.ndarray:
        return self.xy_m[0]

    @property
    def y_m(self) -> np.ndarray:
        return self.xy_m[1]

    def with_vehicle(
        self,
        role_index: int,
        x_m: float,
        y_m: float,
        v_m_s: float,
        phi_rad: float,
        radar_on: bool,
        identified: bool,
        step: int,
    ) -> WorldState:
        """One world's state (N = 1) with vehicle ``role_index`` at an outside estimate (a companion's filter) and
        the mission flags and step its datalink tells; the other vehicles and the layout as they were."""
        if self.n != 1:
            raise ValueError(f"with_vehicle sets one world's vehicle, this state holds {self.n}")
        j = role_index
        xy, v, phi = self.xy_m.copy(), self.v_m_s.copy(), self.phi_rad.copy()
        xy[0, 0, j] = x_m
        xy[1, 0, j] = y_m
        v[0, j] = v_m_s
        phi[0, j] = wrap_angle(phi_rad)
        return self._replace(
            xy_m=xy,
            v_m_s=v,
            phi_rad=phi,
            radar_on=np.array([radar_on]),
            identified=np.array([identified]),
            steps=np.array([step], dtype=np.int64),
        )


def snapshot(world: World) -> WorldState:
    """``world``'s state as views of its arrays (valid until it next steps or resets)."""
    return WorldState(
        world.c,
        world.xy_m,
        world.v_m_s,
        world.phi_rad,
        world.sam_m,
        world.target_m,
        world.radar_m,
        world.radar_r_m,
        world.points_xy_m,
        world.sam_xy_m,
        world.has_unused_radar_slots,
        world.radar_on,
        world.identified,
        world.steps,
        world.layout_token,
    )


def initial_state(scenario: Scenario, layout: Layout) -> WorldState:
    """One world (N = 1) at the start of ``layout``: what a World of ``scenario`` reset to it holds (the World that
    builds it is not kept: the one source of the layout's arrays stays :meth:`World.reset`)."""
    world = World(scenario, 1)
    world.reset([0], [layout])
    return snapshot(world)
