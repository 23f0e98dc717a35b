"""Kinematics (eq. 5-6), cost (eq. 11) and mission logic (eq. 9) of tssac_core.sim.world."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tssac_core.sim.scenario import Layout, Radar, Start, load
from tssac_core.sim.world import KM, World, wrap_angle


def layout(sam=(65.0, 65.0), radars=(), starts=None) -> Layout:
    starts = starts or {"decoy": ((10.0, 10.0), 0.0), "detect": ((10.0, 20.0), 0.0), "strike": ((10.0, 30.0), 0.0)}
    return Layout(sam, sam, tuple(Radar(p, r) for p, r in radars), {k: Start(p, h) for k, (p, h) in starts.items()})


@pytest.fixture()
def scenario(strike_path):
    return load(strike_path)


def world_with(scenario, lay: Layout, n: int = 1) -> World:
    w = World(scenario, n)
    w.reset(np.arange(n), [lay] * n)
    return w


def test_straight_flight_is_exact(scenario):
    w = world_with(
        scenario,
        layout(starts={"decoy": ((10.0, 10.0), 30.0), "detect": ((10.0, 20.0), 0.0), "strike": ((10.0, 30.0), 90.0)}),
    )
    for _ in range(100):
        w.step(np.zeros((1, 3, 2)))
    dist = 250.0 * 100 * 0.1
    np.testing.assert_allclose(
        w.x_m[0], [10 * KM + dist * math.cos(math.radians(30)), 10 * KM + dist, 10 * KM], atol=1e-3
    )
    np.testing.assert_allclose(
        w.y_m[0], [10 * KM + dist * math.sin(math.radians(30)), 20 * KM, 30 * KM + dist], atol=1e-3
    )


def test_constant_rate_circle_closes(scenario):
    w = world_with(scenario, layout())
    omega = math.radians(scenario.vehicle(scenario_role("decoy")).turn_rate_max_deg_s)
    steps = round(2 * math.pi / omega / 0.1)  # 5 deg/s -> exactly 720 steps of 0.1 s
    x0, y0 = w.x_m.copy(), w.y_m.copy()
    action = np.zeros((1, 3, 2))
    action[..., 0] = 1.0
    xs = []
    for _ in range(steps):
        w.step(action)
        xs.append(w.x_m[0, 0])
    np.testing.assert_allclose(w.x_m, x0, atol=1e-6)
    np.testing.assert_allclose(w.y_m, y0, atol=1e-6)
    radius = 250.0 / omega  # eq. 5: a circle of radius v / omega, to the left (counter-clockwise)
    assert max(xs) - min(xs) == pytest.approx(2 * radius, rel=1e-4)
    assert w.phi_rad[0, 0] == pytest.approx(0.0, abs=1e-9)


def scenario_role(name):
    from tssac_core.sim.scenario import Role

    return Role(name)


def test_headings_wrap_into_minus_pi_to_pi():
    """Eq. 6's heading bound: every angle maps into [-pi, pi), the same direction, arrays and scalars alike."""
    assert wrap_angle(math.pi) == -math.pi and wrap_angle(-math.pi) == -math.pi
    assert wrap_angle(1.5 * math.pi) == pytest.approx(-0.5 * math.pi) and wrap_angle(-2.5 * math.pi) == pytest.approx(
        -0.5 * math.pi
    )
    angles = np.linspace(-20.0, 20.0, 101)
    wrapped = wrap_angle(angles)
    assert np.all(wrapped >= -math.pi) and np.all(wrapped < math.pi)
    np.testing.assert_allclose(np.sin(wrapped), np.sin(angles), atol=1e-12)
    np.testing.assert_allclose(np.cos(wrapped), np.cos(angles), atol=1e-12)


def test_speed_and_heading_bounds(scenario):
    w = world_with(scenario, layout())
    action = np.zeros((1, 3, 2))
    action[0, 0, 1] = 5.0  # beyond [-1, 1]: clipped to +1 = 10 m/s^2
    action[0, 1, 1] = -1.0
    action[0, 2, 0] = -1.0
    for _ in range(100):
        w.step(action)
    assert w.v_m_s[0, 0] == pytest.approx(300.0)  # v_max after 10 s at 10 m/s^2 from 250
    assert w.v_m_s[0, 1] == pytest.approx(150.0)  # v_min
    assert -math.pi <= w.phi_rad[0, 2] < math.pi
    assert w.phi_rad[0, 2] == pytest.approx(-math.radians(50.0))
    w.step(np.full((1, 3, 2), 0.5))
    assert w.v_m_s[0, 0] == pytest.approx(300.0)


def test_leaving_the_area_terminates(scenario):
    w = world_with(
        scenario,
        layout(starts={"decoy": ((0.1, 50.0), 180.0), "detect": ((10.0, 20.0), 0.0), "strike": ((10.0, 30.0), 0.0)}),
    )
    result = w.step(np.zeros((1, 3, 2)))
    assert not result.terminated[0]
    for _ in range(10):
        result = w.step(np.zeros((1, 3, 2)))
        if result.terminated[0]:
            break
    assert result.terminated[0] and result.out_of_area[0, 0] and not result.out_of_area[0, 1]
    assert not w.running[0]
    x_end = w.x_m.copy()
    w.step(np.zeros((1, 3, 2)))
    np.testing.assert_array_equal(w.x_m, x_end)  # a finished world is frozen


def test_cost_inside_and_outside_radar(scenario):
    lay = layout(
        radars=[((40.0, 40.0), 12.0)],
        starts={"decoy": ((40.0, 27.99), 90.0), "detect": ((40.0, 27.0), 0.0), "strike": ((10.0, 10.0), 0.0)},
    )
    w = world_with(scenario, lay)
    assert w.in_hazard[0].tolist() == [False, False, False]
    r = w.step(np.zeros((1, 3, 2)))  # decoy moves 25 m north: 11.985 km from the centre, inside
    assert r.cost[0].tolist() == [1.0, 0.0, 0.0]
    assert r.hazard_entered[0].tolist() == [True, False, False]
    r = w.step(np.zeros((1, 3, 2)))
    assert r.cost[0].tolist() == [1.0, 0.0, 0.0]
    assert r.hazard_entered[0].tolist() == [False, False, False]
    assert w.cost_total[0, 0] == 2.0


def place(w: World, d_km: tuple[float, float, float]) -> None:
    """Put the three UAVs on a line east of the SAM at the given distances, flying north (tangent)."""
    for j, d in enumerate(d_km):
        w.x_m[0, j] = w.sam_m[0, 0] + d * KM
        w.y_m[0, j] = w.sam_m[0, 1]
        w.phi_rad[0, j] = math.pi / 2
    w.v_m_s[0] = 150.0


STILL = np.zeros((1, 3, 2))


@pytest.mark.parametrize(
    "distances, radar_on, identified, hit",
    [
        ((18.5, 11.5, 5.0), True, True, True),  # everyone in their zone at once: success
        ((16.5, 11.5, 5.0), False, False, False),  # decoy inside R3: radar off, nothing follows
        ((20.5, 11.5, 5.0), False, False, False),  # decoy beyond R4
        ((18.5, 13.5, 5.0), True, False, False),  # detect beyond R2: no identification
        ((18.5, 9.5, 5.0), True, False, False),  # detect inside R1 is not its zone
        ((18.5, 11.5, 10.5), True, True, False),  # strike beyond R1: identified but no hit
    ],
)
def test_task_conditions(scenario, distances, radar_on, identified, hit):
    w = world_with(scenario, layout())
    place(w, distances)
    r = w.step(STILL)
    assert (bool(w.radar_on[0]), bool(w.identified[0]), bool(w.hit[0])) == (radar_on, identified, hit)
    assert bool(r.terminated[0]) == hit
    assert r.task_completed[0].tolist() == [radar_on, identified, hit]


def test_conditions_must_hold_at_the_same_time(scenario):
    w = world_with(scenario, layout())
    # Detect in its zone while the radar is off: nothing. Then the decoy arrives: identified (latched).
    place(w, (25.0, 11.5, 30.0))
    w.step(STILL)
    assert not w.identified[0]
    place(w, (18.5, 11.5, 30.0))
    w.step(STILL)
    assert w.identified[0] and w.radar_on[0]
    # The decoy leaves its ring: radar off; the identification stays, but the strike cannot hit.
    place(w, (25.0, 11.5, 5.0))
    r = w.step(STILL)
    assert w.identified[0] and not w.radar_on[0] and not w.hit[0] and r.radar_on_changed[0]
    # Detect out of its zone while the others hold: no hit either (eq. 9 needs all three).
    place(w, (18.5, 15.0, 5.0))
    w.step(STILL)
    assert not w.hit[0]
    place(w, (18.5, 12.0, 5.0))
    r = w.step(STILL)
    assert w.hit[0] and r.hit_now[0] and r.terminated[0]


def test_parked_vehicles_do_not_move_or_count(scenario):
    w = World(scenario, 1)
    lay = layout(radars=[((10.0, 20.0), 5.0)])
    w.reset([0], [lay], active=(True, False, False))
    y0 = w.y_m.copy()
    r = w.step(np.ones((1, 3, 2)))
    assert r.cost[0].tolist() == [0.0, 0.0, 0.0]  # detect sits inside the radar but is parked
    assert w.y_m[0, 1] == y0[0, 1] and w.y_m[0, 0] != y0[0, 0]


def test_episode_cap_truncates(scenario):
    w = world_with(
        scenario,
        layout(starts={"decoy": ((50.0, 10.0), 0.0), "detect": ((50.0, 20.0), 0.0), "strike": ((50.0, 30.0), 0.0)}),
    )
    action = np.zeros((1, 3, 2))
    action[..., 0] = 1.0  # circle forever
    for t in range(scenario.episode_steps):
        r = w.step(action)
        assert bool(r.truncated[0]) == (t == scenario.episode_steps - 1)
    assert not r.terminated[0]


def test_batched_worlds_are_independent(scenario):
    """One step of N worlds equals N single-world steps (the single env is the batched world with N=1)."""
    rng = np.random.default_rng(0)
    lays = [
        layout(
            starts={
                "decoy": ((10.0 + i, 10.0), 10.0 * i),
                "detect": ((10.0, 20.0 + i), 0.0),
                "strike": ((10.0, 30.0), 5.0 * i),
            }
        )
        for i in range(5)
    ]
    big = World(scenario, 5)
    big.reset(np.arange(5), lays)
    singles = [world_with(scenario, lay) for lay in lays]
    for _ in range(50):
        a = rng.uniform(-1, 1, (5, 3, 2))
        big.step(a)
        for i, s in enumerate(singles):
            s.step(a[i : i + 1])
    for i, s in enumerate(singles):
        np.testing.assert_array_equal(big.x_m[i], s.x_m[0])
        np.testing.assert_array_equal(big.phi_rad[i], s.phi_rad[0])
