"""The runtime-assurance monitor: hostile policies stay out of the radars and inside the area, the
hysteresis bounds the switches, and one vehicle's monitor decides as the batched world's does."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mavlink_bridge.companion.shield import CompanionShield
from mavlink_bridge.estimation.state_filter import FilterNoise, VehicleStateFilter
from tssac_core.assurance.monitor import (
    Hazards,
    Limits,
    Memory,
    ShieldConfig,
    backup_clearance,
    circle_clearance,
    companion_error,
    companion_margin_m,
    constant_rollout,
    decide,
)
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.observation import ObservationMode, observe
from tssac_core.sim.scenario import Role, load, sample_layout
from tssac_core.sim.world import World
from tssac_core.sim.world_monitor import VehicleMonitor, WorldMonitor
from tssac_core.sim.world_state import snapshot


class SteerIntoRadar:
    """A hostile policy: full speed, full turn towards the nearest radar's centre (1 s decisions)."""

    observation_mode = ObservationMode.EXTENDED
    action_repeat = 10

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        bearing = np.arctan2(obs[:, 13], obs[:, 12])  # nearest radar, relative to the heading
        return np.stack([np.clip(3.0 * bearing, -1.0, 1.0), np.ones(len(obs))], axis=1)


class SteerOutOfArea:
    """A hostile policy: full speed, full turn towards the nearest edge of the area."""

    observation_mode = ObservationMode.EXTENDED
    action_repeat = 10

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        x, y = obs[:, 0], obs[:, 1]
        edges = np.stack([x, 1 - x, y, 1 - y], axis=1)
        target = np.array([math.pi, 0.0, -math.pi / 2, math.pi / 2])[np.argmin(edges, axis=1)]
        err = np.angle(np.exp(1j * (target - np.arctan2(obs[:, 4], obs[:, 3]))))
        return np.stack([np.clip(3.0 * err, -1.0, 1.0), np.ones(len(obs))], axis=1)


@pytest.fixture
def short_random(random_path):
    return dataclasses.replace(load(random_path), episode_steps=1500)


def test_policy_steering_into_radars_never_enters_one(short_random):
    pilots = [SteerIntoRadar()] * 3
    alone = fly_missions(short_random, pilots, episodes=8, seed=31)
    assert (alone.cost > 0).mean() > 0.9  # the policy does reach the radars on its own
    shielded = fly_missions(short_random, pilots, episodes=8, seed=31, shield=ShieldConfig())
    assert shielded.cost.max() == 0.0
    assert not shielded.out_of_area.any()
    assert shielded.monitor is not None and shielded.monitor.interventions.min() >= 1
    assert shielded.monitor.unprotected_steps.sum() == 0


def test_policy_steering_out_of_the_area_stays_in(short_random):
    pilots = [SteerOutOfArea()] * 3
    alone = fly_missions(short_random, pilots, episodes=8, seed=32)
    assert alone.out_of_area.any(axis=1).all()  # every mission ends with a UAV out of the area
    shielded = fly_missions(short_random, pilots, episodes=8, seed=32, shield=ShieldConfig())
    assert not shielded.out_of_area.any()
    assert shielded.cost.max() == 0.0
    assert (shielded.time_s == short_random.episode_steps * short_random.dt_s).all()  # flown to the cap, inside


def test_hysteresis_bounds_the_switches(short_random):
    """Steering into a radar makes a monitor without hysteresis hand over and back again and again."""
    pilots = [SteerIntoRadar()] * 3
    loose = ShieldConfig(release_margin_m=0.0, release_decisions=1)
    chatter = fly_missions(short_random, pilots, episodes=4, seed=33, shield=loose)
    held = fly_missions(short_random, pilots, episodes=4, seed=33, shield=ShieldConfig())
    assert chatter.monitor is not None and held.monitor is not None
    assert chatter.cost.max() == 0.0 and held.cost.max() == 0.0
    decisions = short_random.episode_steps // SteerIntoRadar.action_repeat
    assert chatter.monitor.switches.max() > decisions / 4  # a hand-over every few decisions
    # Each engagement lasts at least release_decisions decisions: at most one switch pair per 3 + 1 decisions.
    cfg = ShieldConfig()
    assert held.monitor.switches.max() <= 2 * decisions / (cfg.release_decisions + 1)
    assert held.monitor.switches.max() * 4 < chatter.monitor.switches.max()


def test_vehicle_monitor_decides_as_the_batched_world(short_random):
    """The companion's monitor (one vehicle, its own calls) and the batched world's take the same decisions."""
    scenario = dataclasses.replace(short_random, episode_steps=600)
    rng = np.random.default_rng(34)
    layouts = [sample_layout(scenario, rng) for _ in range(3)]
    world = World(scenario, len(layouts))
    world.reset(np.arange(len(layouts)), layouts)
    cfg = ShieldConfig()
    batched = WorldMonitor(world, [10] * 3, cfg)
    singles = {}
    for i, lay in enumerate(layouts):
        one = World(scenario, 1)
        one.reset([0], [lay])
        for j in range(3):
            singles[i, j] = VehicleMonitor(snapshot(one), j, cfg)
    pilot = SteerIntoRadar()
    engaged_seen = 0
    while world.running.any() and world.steps[0] < scenario.episode_steps:
        proposed = np.stack([pilot(observe(snapshot(world), j, pilot.observation_mode)) for j in range(3)], axis=1)
        due = world.steps[0] % 10 == 0
        state = (world.x_m.copy(), world.y_m.copy(), world.v_m_s.copy(), world.phi_rad.copy())
        actions = batched.actions(world, proposed)
        if due:
            for (i, j), mon in singles.items():
                if not world.running[i]:
                    continue
                d = mon.decide(
                    state[0][i, j], state[1][i, j], state[2][i, j], state[3][i, j], proposed[i, j], 10, cfg.margin_m
                )
                np.testing.assert_array_equal(d.action[0], actions[i, j])
                assert bool(d.engaged[0]) == bool(batched.engaged[i, j])
                engaged_seen += int(d.engaged[0])
        world.step(actions)
    assert engaged_seen > 0  # the comparison covered decisions under the backup too


def test_backups_are_what_the_world_flies(random_path):
    """A constant-speed maximum-rate turn flown by the world stays on the circle the monitor checks, and the
    monitor's rollout is the world's eq. 5 integration."""
    s = load(random_path)
    world = World(s, 1)
    world.reset([0], [sample_layout(s, np.random.default_rng(1))])
    x, y, v, phi = world.x_m[0, 0], world.y_m[0, 0], world.v_m_s[0, 0], world.phi_rad[0, 0]
    c = world.c
    lim = Limits(c.speed_min_m_s[:1], c.speed_max_m_s[:1], c.turn_rate_max_rad_s[:1], c.accel_max_m_s2[:1])
    action = np.array([[1.0, 0.0]])
    xs, ys, _, _ = constant_rollout(
        np.array([x]), np.array([y]), np.array([v]), np.array([phi]), action, lim, c.dt_s, 720
    )
    r = v / c.turn_rate_max_rad_s[0]
    cx, cy = x - r * math.sin(phi), y + r * math.cos(phi)
    flown = []
    for _ in range(720):
        world.step(np.tile(np.array([1.0, 0.0]), (1, 3, 1)))
        flown.append((world.x_m[0, 0], world.y_m[0, 0]))
    flown_xy = np.array(flown)
    np.testing.assert_allclose(flown_xy[:, 0], xs[0], atol=1e-6)
    np.testing.assert_allclose(flown_xy[:, 1], ys[0], atol=1e-6)
    np.testing.assert_allclose(np.hypot(flown_xy[:, 0] - cx, flown_xy[:, 1] - cy), r, atol=1e-6)
    # The braking turn: 15 s of spiral from 300 m/s down to v_min, then the 1.72 km circle.
    world.reset([0], [sample_layout(s, np.random.default_rng(1))])
    world.v_m_s[0, 0] = 300.0
    x, y, phi = world.x_m[0, 0], world.y_m[0, 0], world.phi_rad[0, 0]
    brake = np.array([[-1.0, -1.0]])
    xs, ys, vs, _ = constant_rollout(
        np.array([x]), np.array([y]), np.array([300.0]), np.array([phi]), brake, lim, c.dt_s, 400
    )
    flown = []
    for _ in range(400):
        world.step(np.tile(brake[0], (1, 3, 1)))
        flown.append((world.x_m[0, 0], world.y_m[0, 0], world.v_m_s[0, 0]))
    flown_xyv = np.array(flown)
    np.testing.assert_allclose(flown_xyv[:, 0], xs[0], atol=1e-6)
    np.testing.assert_allclose(flown_xyv[:, 1], ys[0], atol=1e-6)
    np.testing.assert_allclose(flown_xyv[:, 2], vs[0], atol=1e-9)
    assert vs[0, 149] == 150.0 and vs[0, 148] > 150.0


def test_pending_commands_are_flown_first():
    """With commands still on the link, the monitor decides from where they leave the vehicle."""
    hz = Hazards(np.array([[[50_000.0, 50_000.0]]]), np.array([[12_000.0]]), 100_000.0)
    lim = Limits(np.array([150.0]), np.array([300.0]), np.radians([5.0]), np.array([10.0]))
    cfg = ShieldConfig()
    state = np.array([[30_000.0, 45_000.0, 280.0, 0.3]])
    pending = np.tile(np.array([[0.5, 1.0]]), (1, 20, 1))
    proposed = np.array([[-0.2, 0.0]])
    with_queue = decide(state, proposed, Memory.initial(1), hz, lim, 0.1, 10, 100.0, cfg, pending)
    xs, ys, vs, ps = constant_rollout(state[:, 0], state[:, 1], state[:, 2], state[:, 3], pending[:, 0], lim, 0.1, 20)
    moved = np.array([[xs[0, -1], ys[0, -1], vs[0, -1], ps[0, -1]]])
    direct = decide(moved, proposed, Memory.initial(1), hz, lim, 0.1, 10, 100.0, cfg)
    assert with_queue.clearance_m[0] == pytest.approx(direct.clearance_m[0], abs=1e-6)
    assert with_queue.clearance_m[0] != pytest.approx(
        decide(state, proposed, Memory.initial(1), hz, lim, 0.1, 10, 100.0, cfg).clearance_m[0]
    )


def test_circle_clearance_by_hand():
    hz = Hazards(np.array([[[50_000.0, 50_000.0]]]), np.array([[12_000.0]]), 100_000.0)
    # A circle of radius 3 km centred 20 km east of the radar: 20 - 12 - 3 = 5 km from the disk; 27 km from the east
    # edge.
    c = circle_clearance(np.array([70_000.0]), np.array([50_000.0]), np.array([3_000.0]), hz)
    assert c[0] == pytest.approx(5_000.0)
    # ... and 2 km from the north edge when centred at y = 95 km (far from the radar).
    c = circle_clearance(np.array([90_000.0]), np.array([95_000.0]), np.array([3_000.0]), hz)
    assert c[0] == pytest.approx(2_000.0)


def test_head_on_at_a_radar_turns_in_time():
    """Flying straight at a radar, the monitor passes the action while a backup clears the disk and engages
    at the last decision that still has one; the backup then never comes nearer than the margin."""
    hz = Hazards(np.array([[[50_000.0, 50_000.0]]]), np.array([[12_000.0]]), 100_000.0)
    lim = Limits(np.array([150.0]), np.array([300.0]), np.radians([5.0]), np.array([10.0]))
    cfg = ShieldConfig()
    mem = Memory.initial(1)
    state = np.array([[20_000.0, 50_000.0, 300.0, 0.0]])
    engaged_at = None
    for k in range(120):
        d = decide(state, np.array([[0.0, 1.0]]), mem, hz, lim, 0.1, 10, cfg.margin_m, cfg)
        mem = d.memory
        if d.engaged[0] and engaged_at is None:
            engaged_at = k
        xs, ys, vs, ps = constant_rollout(state[:, 0], state[:, 1], state[:, 2], state[:, 3], d.action, lim, 0.1, 10)
        state = np.array([[xs[0, -1], ys[0, -1], vs[0, -1], ps[0, -1]]])
        gap = math.hypot(state[0, 0] - 50_000.0, state[0, 1] - 50_000.0) - 12_000.0
        assert gap >= cfg.margin_m
    assert engaged_at is not None
    # At 300 m/s a constant-speed circle (r = 3.44 km) needs its centre 12 + 3.44 + 0.1 km from the radar's,
    # i.e. a turn sqrt(15.54^2 - 3.44^2) = 15.15 km from the radar's centre; the braking turn (ending on a
    # 1.72 km circle) lets the UAV come a little nearer before it must turn.
    x_at = 20_000.0 + 300.0 * engaged_at
    assert 14_000.0 < 50_000.0 - x_at < 15_150.0
    # The remembered backups all start where the vehicle is: their clearance from there is the margin or more.
    clear = backup_clearance(state[:, 0], state[:, 1], state[:, 2], state[:, 3], hz, lim, 0.1, np.array([0]))
    assert clear.max() >= cfg.margin_m


def test_companion_monitor_margin_and_pending(random_path):
    """The companion's monitor: the same decisions as the batched world's under lockstep with an exact estimate;
    off lockstep it flies the round trip's commands first (the hold before the first one was sent), and its
    margin grows by the timing slack; its error bound by 3 sigma and, over a lossy link, a lost setpoint."""
    s = load(random_path)
    lay = sample_layout(s, np.random.default_rng(35))
    world = World(s, 1)
    world.reset([0], [lay])
    cfg = ShieldConfig()
    lockstep = CompanionShield(snapshot(world), Role.DECOY, s, cfg, lockstep=True)
    reference = VehicleMonitor(snapshot(world), 0, cfg)
    state = (world.x_m[0, 0], world.y_m[0, 0], world.v_m_s[0, 0], world.phi_rad[0, 0])
    for k in range(30):
        proposed = np.array([1.0 if k % 7 < 3 else -0.5, 0.3])
        action, _ = lockstep.action(True, 10, proposed, lambda: (state, (0.0, 0.0, 0.0), (0.0, 0.0)), 10 * k)
        lockstep.sent(action, 10 * k)
        d = reference.decide(*state, proposed, 10, cfg.margin_m)
        np.testing.assert_array_equal(action, d.action[0])
        xs, ys, vs, ps = constant_rollout(*(np.array([q]) for q in state), action[None], reference.limits, s.dt_s, 10)
        state = (xs[0, -1], ys[0, -1], vs[0, -1], ps[0, -1])
    assert lockstep.pending_ticks() == 0 and not lockstep.lossy  # a perfect link in lockstep: nothing in flight
    slow = dataclasses.replace(s, link=dataclasses.replace(s.link, latency_ms=200.0))
    realtime = CompanionShield(snapshot(world), Role.DECOY, slow, cfg, lockstep=False)
    assert realtime.pending_ticks() == 4 and realtime.lossy and realtime.off_lockstep  # 2 x 0.2 s of 0.1 s ticks
    realtime.sent(np.array([1.0, 1.0]), 0)
    pending = realtime._pending()
    assert pending is not None  # the hold flew before the first command: three holds, then the command sent
    np.testing.assert_array_equal(pending, [[0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [1.0, 1.0]])
    # Lockstep over a slow, lossy link (degraded.yaml): the link runs on simulated time, so the round trip is
    # in ticks as well, and a lost setpoint leaves the vehicle on the previous command.
    lossy = dataclasses.replace(s, link=dataclasses.replace(s.link, latency_ms=200.0, packet_loss=0.1))
    degraded = CompanionShield(snapshot(world), Role.DECOY, lossy, cfg, lockstep=True)
    assert degraded.pending_ticks() == 4 and degraded.lossy and not degraded.off_lockstep
    assert companion_margin_m(cfg, 300.0, off_lockstep=True) == pytest.approx(100.0 + 150.0)
    assert companion_margin_m(cfg, 300.0, off_lockstep=False) == pytest.approx(100.0)
    lim = reference.limits
    exact = companion_error(cfg, lim, 0.1, 5.0, 0.002, 0.5, lossy=False)
    assert (exact.position_m[0], exact.heading_rad[0], exact.speed_m_s[0]) == pytest.approx((15.0, 0.006, 1.5))
    with_loss = companion_error(cfg, lim, 0.1, 5.0, 0.002, 0.5, lossy=True)
    w = math.radians(5.0)
    assert with_loss.heading_rad[0] == pytest.approx(0.006 + 2 * w * 0.1)  # one tick of the opposite full turn
    assert with_loss.speed_m_s[0] == pytest.approx(1.5 + 2 * 10.0 * 0.1)


def test_filter_major_axis_sigma():
    f = VehicleStateFilter(
        FilterNoise.from_sensor(15.0, 1.5, max_accel_m_s2=10.0, max_turn_rate_rad_s=math.radians(5.0))
    )
    rng = np.random.default_rng(36)
    for k in range(50):
        t = 0.1 * k
        f.update(
            t, (250.0 * t + rng.normal(0, 15.0), rng.normal(0, 15.0)), (250.0 + rng.normal(0, 1.5), rng.normal(0, 1.5))
        )
    major, drms = f.position_sigma_major_m, f.position_sigma_m
    assert drms / math.sqrt(2) <= major <= drms  # the largest of two variances: between half and all of the trace
    assert 0.5 < major < 15.0  # the filter knows the position better than one fix


def test_in_wind_the_companions_monitor_turns_the_filters_ground_state_into_the_airs_and_back(random_path):
    """With a response whose loiter is fitted, in a scenario's wind: the state the monitor decides on is the air's part
    of the filter's ground velocity (airspeed, heading) and its course rate as the heading rate; dead reckoning gives
    the ground's (carried by the wind). One is the other's inverse; the wind the vehicle reports replaces the
    scenario's, a report that is not finite does not."""
    from sim_vehicles.dynamics.response_fit import response_path
    from tssac_core.sim.airframe_response import load_response
    from tssac_core.sim.scenario import Wind

    s = dataclasses.replace(load(random_path), wind=Wind(speed_m_s=10.0, from_deg=270.0))
    lay = sample_layout(s, np.random.default_rng(35))
    world = World(s, 1)
    world.reset([0], [lay])
    shield = CompanionShield(snapshot(world), Role.DECOY, s, ShieldConfig(), True, load_response(response_path("f16")))
    assert shield.loiter is not None and shield.wind_m_s == pytest.approx((10.0, 0.0))
    shield.set_wind(8.0, -6.0)
    shield.set_wind(float("nan"), 1.0)
    assert shield.wind_m_s == (8.0, -6.0)
    air = (1000.0, 2000.0, 250.0, 1.2)
    ground, course_rate = shield._over_the_ground(air, math.radians(4.0), 10.0)
    assert ground[:2] == pytest.approx((1080.0, 1940.0))  # carried 10 s by (8, -6) m/s
    gx, gy = 250.0 * math.cos(1.2) + 8.0, 250.0 * math.sin(1.2) - 6.0
    assert ground[2:] == pytest.approx((math.hypot(gx, gy), math.atan2(gy, gx)))
    back, sigmas, rate = shield._in_the_air(ground, (5.0, 0.01, 1.0), course_rate)
    assert back == pytest.approx((1080.0, 1940.0, 250.0, 1.2)) and rate == pytest.approx(math.radians(4.0))
    assert sigmas[1] == pytest.approx(0.01 * ground[2] / 250.0)


def test_the_filter_starts_from_the_known_straight_start_until_a_turn_reaches_the_vehicle(random_path):
    """A monitor predicting with a response: at the first fix, before any turn command has reached the vehicle (the
    link's round trip after it was sent), the filter may start from a turn rate of 0 with a small sigma; once one may
    have, from its own prior (None); a monitor predicting with eq. 5 never asks for it."""
    from sim_vehicles.dynamics.response_fit import response_path
    from tssac_core.sim.airframe_response import load_response
    from tssac_core.sim.lagged_starts import STRAIGHT_START_TURN_SIGMA_RAD_S

    s = load(random_path)
    world = World(s, 1)
    world.reset([0], [sample_layout(s, np.random.default_rng(35))])
    response = load_response(response_path("f16"))
    shield = CompanionShield(snapshot(world), Role.DECOY, s, ShieldConfig(), True, response)
    eq5 = CompanionShield(snapshot(world), Role.DECOY, s, ShieldConfig(), True)
    delay = shield.pending_ticks()
    assert shield.straight_start_turn_rate(0) == (0.0, STRAIGHT_START_TURN_SIGMA_RAD_S)
    shield.sent((0.0, 1.0), 0, before_fix=True)  # straight on, faster: still no turn
    shield.sent((0.5, 0.0), 3, before_fix=True)
    assert shield.straight_start_turn_rate(3 + delay - 1) == (0.0, STRAIGHT_START_TURN_SIGMA_RAD_S)
    assert shield.straight_start_turn_rate(3 + delay) is None
    assert eq5.straight_start_turn_rate(0) is None


def test_in_wind_the_companions_backup_turns_in_for_its_turn_in_then_loiters_from_where_it_ends(random_path):
    """The companion's monitor flies a backup in wind as its prediction does: after the lead, exactly the turn-in's
    ticks of the maximum-rate turn its way, then the loiter law on the circle fixed from the estimate at the tick the
    turn-in ends (a pilot whose proposals are not finite: the backup flies from the first decision)."""
    from sim_vehicles.dynamics.response_fit import response_path
    from tssac_core.assurance.ground_loiter import loiter_action, loiter_centre
    from tssac_core.sim.airframe_response import load_response
    from tssac_core.sim.scenario import Wind

    s = dataclasses.replace(load(random_path), wind=Wind(speed_m_s=10.0, from_deg=200.0))
    world = World(s, 1)
    world.reset([0], [sample_layout(s, np.random.default_rng(35))])
    shield = CompanionShield(snapshot(world), Role.DECOY, s, ShieldConfig(), True, load_response(response_path("f16")))
    assert shield.loiter is not None
    turn_in = shield.loiter.turn_in_steps(s.dt_s)
    limit = float(shield.monitor.limits.turn_rate_max_rad_s[0])
    x, y, ground, course = float(world.x_m[0, 0]), float(world.y_m[0, 0]), 260.0, float(world.phi_rad[0, 0])
    commands, estimates = [], []
    for tick in range(turn_in + 400):
        estimate = ((x, y, ground, course), (0.0, 0.0, 0.0), (0.0, 0.0))
        action, _ = shield.action(True, 1, np.full(2, np.nan), lambda e=estimate: e, tick)
        shield.sent(action, tick)
        commands.append(float(action[0]))
        estimates.append(estimate[0])
        course += action[0] * limit * s.dt_s  # the estimate turns as commanded (enough for the timing)
        x, y = x + ground * math.cos(course) * s.dt_s, y + ground * math.sin(course) * s.dt_s
    omega = np.array(commands)
    lead = int(np.argmax(omega != 0.0))
    assert np.all(omega[:lead] == 0.0)
    turn = omega[lead : lead + turn_in]
    assert np.all(np.abs(turn) == 1.0) and np.all(turn == turn[0])
    start = lead + turn_in
    we, wn = shield.wind_m_s
    cx0, cy0, g0, c0 = estimates[start]
    gx, gy = g0 * math.cos(c0), g0 * math.sin(c0)
    radius = shield.loiter.radius_m(np.array([math.hypot(gx - we, gy - wn)]), np.array([limit]))
    centre = loiter_centre(np.array([cx0]), np.array([cy0]), np.array([gx]), np.array([gy]), turn[0], radius)
    for k in range(start, start + 5):
        ex, ey, eg, ec = estimates[k]
        law = loiter_action(
            np.array([ex]), np.array([ey]), np.array([eg * math.cos(ec)]), np.array([eg * math.sin(ec)]), we, wn,
            (*centre, radius, turn[0]), np.array([limit]), shield.loiter.law,
        )  # fmt: skip
        assert omega[k] == pytest.approx(law[0, 0], rel=1e-9, abs=1e-12)


def _fly_first_backup(shield: CompanionShield, world: World, ticks: int, unmodelled_turn_rad: float) -> tuple:
    """Ticks of a companion whose pilot never proposes (its backup flies from the first decision), the vehicle turning
    as commanded and by ``unmodelled_turn_rad`` more, spread over its first seconds (a roll-out the model did not
    predict); the estimate is the truth: (commands, positions (x, y), courses)."""
    limit = float(shield.monitor.limits.turn_rate_max_rad_s[0])
    x, y, course = float(world.x_m[0, 0]), float(world.y_m[0, 0]), float(world.phi_rad[0, 0])
    commands, xy, courses = [], [], []
    for tick in range(ticks):
        estimate = ((x, y, 250.0, course), (0.0, 0.0, 0.0), (0.0, 0.0))
        action, _ = shield.action(True, 1, np.full(2, np.nan), lambda e=estimate: e, tick)
        shield.sent(action, tick)
        commands.append(float(action[0]))
        course += action[0] * limit * 0.1 + unmodelled_turn_rad / 3.0 * math.exp(-0.1 * tick / 3.0) * 0.1
        x, y = x + 250.0 * math.cos(course) * 0.1, y + 250.0 * math.sin(course) * 0.1
        xy.append((x, y))
        courses.append(course)
    return np.array(commands), np.array(xy), np.array(courses)


def test_in_calm_air_the_companions_held_lead_flies_open_then_holds_its_line_and_an_open_one_drifts(random_path):
    """A response with held leads, calm air, the monitor offered only leads of 64 and 128 s: the backup's lead flies
    straight for ``held_after_s``, then the line law on the line through where the vehicle is then, along the course the
    check predicted, until its turn; a vehicle that turns 3 degrees the model did not predict comes back to that
    line. The same backup from a response without held leads (flown open to its end) ends hundreds of metres off
    it (the negative control)."""
    from sim_vehicles.dynamics.response_fit import response_path
    from tssac_core.assurance.held_course import cross_track_m
    from tssac_core.sim.airframe_response import load_response

    s = load(random_path)
    world = World(s, 1)
    world.reset([0], [sample_layout(s, np.random.default_rng(35))])
    fitted = load_response(response_path("f16"))
    held = dataclasses.replace(fitted, held_leads_s=(64.0, 128.0), held_residual_m=fitted.turn_residual_m)
    open_ = dataclasses.replace(fitted, held_leads_s=(), held_residual_m=())
    cfg = ShieldConfig(straight_leads_s=(64.0,))
    shield = CompanionShield(snapshot(world), Role.DECOY, s, cfg, True, held)
    assert shield.cfg.straight_leads_s == (64.0, 128.0)
    hold_from = round(held.held_after_s / s.dt_s)
    omega, xy, _ = _fly_first_backup(shield, world, 640 + 20, math.radians(3.0))
    lead = int(np.argmax(np.abs(omega) == 1.0))
    assert lead == 640 and np.all(omega[lead:] == omega[lead])  # the 64 s lead's backup, then its turn
    assert np.all(omega[:hold_from] == 0.0) and np.any(omega[hold_from:lead] != 0.0)  # open, then the law steers
    assert shield.counters.held_steps == lead - hold_from and shield._line is None  # the turn ended the hold
    line_x, line_y = xy[hold_from - 1]  # the estimate where the hold began
    line_course = float(shield.monitor.memory.held_course[0])
    off = cross_track_m(*(np.array([a]) for a in (*xy[lead - 1], line_x, line_y, line_course)))
    assert abs(float(off[0])) < 50.0  # back on the line

    control = CompanionShield(snapshot(world), Role.DECOY, s, ShieldConfig(straight_leads_s=(64.0,)), True, open_)
    omega_open, xy_open, _ = _fly_first_backup(control, world, 640, math.radians(3.0))
    assert np.all(omega_open[:639] == 0.0) and control.counters.held_steps == 0
    drift = cross_track_m(*(np.array([a]) for a in (*xy_open[-1], line_x, line_y, line_course)))
    assert abs(float(drift[0])) > 300.0  # 3 degrees over 32 s flown open
