"""Route distances on the grid: the wavefront's metric, obstacles, hazard weights, and the detour."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tssac_core.sim.routes import (
    KING_MOVES,
    KNIGHT_MOVES,
    RouteConfig,
    RouteMap,
    sample_bilinear,
    wavefront,
)
from tssac_core.sim.scenario import Layout, Radar, Role, Start, load
from tssac_core.sim.world import World
from tssac_core.sim.world_state import snapshot


def corner_goal(size: int = 21) -> np.ndarray:
    goal = np.zeros((size, size), dtype=bool)
    goal[0, 0] = True
    return goal


def test_free_grid_distances_are_the_chamfer_metrics():
    goal = corner_goal()
    king = wavefront(goal, np.ones(goal.shape), KING_MOVES)
    assert king[20, 0] == pytest.approx(20.0)
    assert king[20, 20] == pytest.approx(20 * math.sqrt(2))
    assert king[20, 10] == pytest.approx(10 + 10 * math.sqrt(2))  # octile: 8% over the straight 22.4
    knight = wavefront(goal, np.ones(goal.shape), KNIGHT_MOVES)
    assert knight[20, 10] == pytest.approx(10 * math.sqrt(5))  # exact along a knight's direction
    straight = np.hypot(*np.indices(goal.shape))
    ratio = knight[1:, 1:] / straight[1:, 1:]
    assert ratio.min() >= 1.0 - 1e-12 and ratio.max() < 1.03


def test_walls_are_flown_around_and_hazards_cost_their_weight():
    size = 21
    goal = np.zeros((size, size), dtype=bool)
    goal[10, 0] = True
    wall = np.zeros((size, size), dtype=bool)
    wall[3:18, 5] = True  # a wall across the way, open at both ends
    blocked = wavefront(goal, np.where(wall, np.inf, 1.0))
    free = wavefront(goal, np.ones((size, size)))
    assert blocked[10, 10] > free[10, 10] + 4  # the way round the end of the wall
    assert np.isinf(blocked[10, 5])  # inside the wall: impassable
    weighted = wavefront(goal, np.where(wall, 3.0, 1.0))
    # Straight through: 9 free cells and one move into and one out of the wall cell at weight 3.
    assert weighted[10, 10] == pytest.approx(min(8 + 2 * (1 + 3) / 2, blocked[10, 10]))
    enclosed = np.zeros((size, size), dtype=bool)
    enclosed[8:13, 8:13] = True
    enclosed[9:12, 9:12] = False
    boxed = wavefront(goal, np.where(enclosed, np.inf, 1.0))
    assert np.isinf(boxed[10, 10])  # boxed in: no way to the goal


def test_bilinear_sampling_is_exact_on_linear_fields():
    i, j = np.indices((10, 10)).astype(np.float32)
    fields = (3 * i + 2 * j)[None]
    x = np.array([[2500.0, 7250.0]])
    y = np.array([[1500.0, 500.0]])
    # Cell centres at (k + 0.5) km: x = 2.5 km is i = 2, y = 1.5 km is j = 1.
    np.testing.assert_allclose(sample_bilinear(fields, 1000.0, x, y), [[3 * 2 + 2 * 1, 3 * 6.75 + 2 * 0]], rtol=1e-6)


def one_radar_layout(radar_km: tuple[float, float], uav_km: tuple[float, float]) -> Layout:
    return Layout(
        sam_km=(70.0, 50.0),
        target_km=(70.0, 51.0),
        radars=(Radar(position_km=radar_km, radius_km=12.0),),
        starts={r.value: Start(position_km=uav_km, heading_deg=0.0) for r in Role},
    )


def one_radar_world(radar_km: tuple[float, float], uav_km: tuple[float, float]) -> World:
    w = World(load("scenarios/strike.yaml"), 1)
    w.reset(np.arange(1), [one_radar_layout(radar_km, uav_km)])
    return w


def test_detour_behind_a_radar_is_the_way_round_it():
    routes = RouteMap(RouteConfig(grid_m=1000.0, margin_m=0.0, hazard_weight=1e6))
    # Free line of sight: no detour (up to the metric's 2.7%).
    clear = routes.detour_m(snapshot(one_radar_world((30.0, 85.0), (10.0, 50.0))))
    assert clear.max() < 0.03 * (60_000 - 20_000)
    # A radar of 12 km radius halfway on the line: the way is tangent, arc, tangent to the 20 km disk.
    blocked = routes.detour_m(snapshot(one_radar_world((30.0, 50.0), (10.0, 50.0))))[0, 0]
    # The shortest way from (10, 50) to the 20 km disk round (70, 50) past a 12 km disk round (30, 50):
    # tangent to the radar (16 km), along its edge from 126.9 deg to 72.5 deg (11.4 km), then on the
    # tangent through the SAM to the disk (38.2 - 20 km); 45.5 km against 40 km straight.
    arc = math.radians((180 - math.degrees(math.acos(12 / 20))) - math.degrees(math.acos(12 / 40))) * 12
    way = math.sqrt(20**2 - 12**2) + arc + math.sqrt(40**2 - 12**2) - 20
    # The grid's metric and the rasterised disk make the way up to 3% longer than the exact one.
    assert (way - 40.0) * 1000 <= blocked <= (way - 40.0) * 1000 + 0.03 * way * 1000
    # Inside the SAM's detection disk the detour is zero.
    inside = routes.detour_m(snapshot(one_radar_world((30.0, 85.0), (60.0, 50.0))))
    assert np.all(inside == 0.0)
    # One vehicle's detour is that column of all of them.
    w = one_radar_world((30.0, 50.0), (10.0, 50.0))
    np.testing.assert_array_equal(routes.detour_m(snapshot(w), 1), routes.detour_m(snapshot(w))[:, 1])


def test_field_cache_rebuilds_only_for_new_layouts():
    routes = RouteMap()
    w = one_radar_world((30.0, 50.0), (10.0, 50.0))
    first = routes.cache.fields(snapshot(w)).copy()
    builds: list[int] = []
    build = routes.cache.build
    routes.cache.build = lambda world, k: (builds.append(k), build(world, k))[1]
    routes.detour_m(snapshot(w))
    w.step(np.zeros((1, 3, 2)))
    routes.detour_m(snapshot(w))
    assert builds == []  # same layout: no rebuild
    w.reset(np.arange(1), [one_radar_layout((30.0, 20.0), (10.0, 50.0))])
    routes.detour_m(snapshot(w))
    assert builds == [0]
    assert not np.array_equal(first, routes.cache.fields(snapshot(w)))
    # Another World whose layout ids coincide but whose radars differ: rebuilt too.
    other = one_radar_world((30.0, 80.0), (10.0, 50.0))
    routes.detour_m(snapshot(other))
    assert builds == [0, 0]


def test_an_edge_margin_makes_the_band_inside_the_area_edge_a_hazard_and_nothing_else():
    plain = RouteMap(RouteConfig(margin_m=0.0))
    banded = RouteMap(RouteConfig(margin_m=0.0, edge_margin_m=3000.0))
    # In the band (1 km from the west edge): the way out of it, about 2 km, costs 5 times its length (the grid: 1.5-2).
    edge = snapshot(one_radar_world((30.0, 85.0), (1.0, 50.0)))
    assert banded.detour_m(edge)[0, 0] >= plain.detour_m(edge)[0, 0] + 4 * 1500
    # Away from the edges, on a free line to the SAM, the way is the same.
    middle = snapshot(one_radar_world((30.0, 85.0), (20.0, 50.0)))
    np.testing.assert_allclose(banded.detour_m(middle)[0, 0], plain.detour_m(middle)[0, 0])
