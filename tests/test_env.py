"""The gymnasium CMDP environment: API, reward terms, observations, determinism, pickling."""

from __future__ import annotations

import math
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import tssac_core.sim.env  # noqa: F401  (registers the environments)
from tssac_core.sim.env import RoleTask
from tssac_core.sim.observation import EXTENDED_SIZE, ObservationMode, observation_bounds, observe
from tssac_core.sim.reward import RewardConfig, reward
from tssac_core.sim.scenario import Role, load
from tssac_core.sim.world import KM, StepResult
from tssac_core.sim.world_state import snapshot


@pytest.mark.parametrize("role", ["Decoy", "Detect", "Strike"])
@pytest.mark.parametrize("observation", ["paper", "extended", "route"])
def test_check_env(role, observation):
    env = gym.make(f"tssac/{role}-v0", observation=observation)
    check_env(env.unwrapped)
    assert env.observation_space.shape == (
        {"paper": 5, "extended": EXTENDED_SIZE, "route": EXTENDED_SIZE + 2}[observation],
    )


def rollout(env, seed, steps=300):
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    trace = [obs]
    for _ in range(steps):
        obs, r, term, trunc, info = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
        trace.append(np.concatenate([obs, [r, info["cost"], term, trunc]]))
        if term or trunc:
            obs, _ = env.reset()
    return np.concatenate(trace)


def test_same_seed_same_rollout():
    a = rollout(gym.make("tssac/Detect-v0"), 11)
    b = rollout(gym.make("tssac/Detect-v0"), 11)
    c = rollout(gym.make("tssac/Detect-v0"), 12)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_pickle_round_trip():
    env = gym.make("tssac/Strike-v0", scenario="scenarios/strike.yaml").unwrapped
    env.reset(seed=3)
    for _ in range(20):
        env.step(np.array([0.3, -0.2], dtype=np.float32))
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(50):
        a = np.array([0.1, 0.5], dtype=np.float32)
        o1, r1, *_ = env.step(a)
        o2, r2, *_ = clone.step(a)
        np.testing.assert_array_equal(o1, o2)
        assert r1 == r2


def test_observations_stay_in_bounds_and_paper_layout(random_path):
    s = load(random_path)
    for mode in ObservationMode:
        task = RoleTask(s, Role.DETECT, n=16, observation=mode, seed=0)
        low, high = observation_bounds(mode)
        obs = task.reset()
        rng = np.random.default_rng(0)
        for _ in range(400):
            assert obs.dtype == np.float32 and obs.shape == (16, mode.size)
            assert (obs >= low).all() and (obs <= high).all()
            obs = task.step(rng.uniform(-1, 1, (16, 2))).obs
    # Paper mode is eq. 7: [x, y, v, phi, l] normalised.
    task = RoleTask(s, Role.DECOY, n=1, observation=ObservationMode.PAPER, seed=1)
    obs = task.reset()[0]
    w = task.world
    assert obs[0] == pytest.approx(w.x_m[0, 0] / (100 * KM), abs=1e-6)
    assert obs[1] == pytest.approx(w.y_m[0, 0] / (100 * KM), abs=1e-6)
    assert obs[2] == pytest.approx((250 - 150) / 150, abs=1e-6)
    assert obs[3] == pytest.approx(w.phi_rad[0, 0] / math.pi, abs=1e-6)
    assert obs[4] == pytest.approx(math.dist((w.x_m[0, 0], w.y_m[0, 0]), w.target_m[0]) / (100 * KM), abs=1e-6)


def test_extended_observation_geometry(strike_path):
    task = RoleTask(load(strike_path), Role.STRIKE, n=1, seed=0)
    obs = task.reset()[0]
    w = task.world
    # SAM bearing relative to heading: strike at (12, 12) km heading 45 deg, SAM at (65, 65): dead ahead.
    assert obs[6] == pytest.approx(1.0, abs=1e-6) and obs[7] == pytest.approx(0.0, abs=1e-6)
    d_sam = math.dist((12, 12), (65, 65)) * KM
    assert obs[8] == pytest.approx(d_sam / (100 * KM), abs=1e-6)
    assert obs[9] == pytest.approx(1.0)  # far outside the strike zone: clipped
    # Nearest radar first: (30, 21) is 20.1 km away, edge 8.1 km -> 0.406 of the 20 km scale.
    assert obs[11] == pytest.approx((math.dist((12, 12), (30, 21)) - 12) / 20, abs=1e-5)
    assert obs[14] >= obs[11] and obs[17] >= obs[14]
    assert obs[20] == 0.0 and obs[21] == 0.0
    assert w.radar_on[0] == 0


def test_route_observation_points_the_way_around_the_radars(strike_path):
    """Route mode = extended + the route direction relative to the heading; a unit vector that bends
    away from the SAM's bearing when radars block the line, and is the SAM's bearing inside its disk."""
    s = load(strike_path)
    task = RoleTask(s, Role.STRIKE, n=1, observation=ObservationMode.ROUTE, seed=0)
    obs = task.reset()[0]
    extended = RoleTask(s, Role.STRIKE, n=1, observation=ObservationMode.EXTENDED, seed=0).reset()[0]
    np.testing.assert_array_equal(obs[:EXTENDED_SIZE], extended)
    assert obs[22] ** 2 + obs[23] ** 2 == pytest.approx(1.0, abs=1e-5)
    # The paper's mission: radars at (38, 44), (30, 21), (62, 26) lie across the line from (12, 12) to
    # (65, 65) (SAM dead ahead); the way round them leaves the line by a clear angle.
    route_angle = math.degrees(math.atan2(obs[23], obs[22]))
    assert abs(route_angle) > 10.0
    # Inside the SAM's detection disk the route is the SAM's bearing.
    w = task.world
    w.x_m[0, 2], w.y_m[0, 2], w.phi_rad[0, 2] = 60_000.0, 60_000.0, 0.3
    inside = observe(snapshot(w), 2, ObservationMode.ROUTE, task.obs_routes)[0]
    assert inside[22] == pytest.approx(inside[6], abs=1e-5) and inside[23] == pytest.approx(inside[7], abs=1e-5)
    with pytest.raises(ValueError, match="route direction"):
        observe(snapshot(w), 2, ObservationMode.ROUTE)


def result(**kw) -> StepResult:
    z = np.zeros((1, 3))
    zb = np.zeros((1, 3), dtype=bool)
    base = dict(
        cost=z,
        zone_dist_prev_m=z,
        zone_dist_m=z,
        in_zone=zb,
        task_completed=zb,
        out_of_area=zb,
        hazard_entered=zb,
        radar_on_changed=np.zeros(1, bool),
        identified_now=np.zeros(1, bool),
        hit_now=np.zeros(1, bool),
        terminated=np.zeros(1, bool),
        truncated=np.zeros(1, bool),
        moving=np.ones((1, 3), bool),
    )
    base.update(kw)
    return StepResult(**base)


MOVING = np.ones((1, 3), dtype=bool)


def test_reward_terms():
    cfg = RewardConfig()
    # Step penalty alone (eq. 10, k3 r_step).
    np.testing.assert_allclose(reward(result(), MOVING, cfg), [[-0.1, -0.1, -0.1]])
    # Approach: 25 m closer to the zone is +0.025 (km); moving away is negative.
    r = reward(
        result(zone_dist_prev_m=np.array([[1000.0, 1000.0, 1000.0]]), zone_dist_m=np.array([[975.0, 1025.0, 1000.0]])),
        MOVING,
        cfg,
    )
    np.testing.assert_allclose(r, [[-0.075, -0.125, -0.1]])
    # Success +10 to the role whose task completed (eq. 9).
    done = np.array([[False, True, False]])
    np.testing.assert_allclose(reward(result(task_completed=done), MOVING, cfg), [[-0.1, 9.9, -0.1]])
    # Holding the zone cancels the step penalty.
    np.testing.assert_allclose(reward(result(in_zone=np.array([[True, False, True]])), MOVING, cfg), [[0.0, -0.1, 0.0]])
    # Leaving the area.
    np.testing.assert_allclose(
        reward(result(out_of_area=np.array([[False, False, True]])), MOVING, cfg), [[-0.1, -0.1, -20.1]]
    )
    # Weights scale their terms.
    k = RewardConfig(k1=2.0, k3=0.5)
    np.testing.assert_allclose(reward(result(task_completed=done), MOVING, k), [[-0.05, 19.95, -0.05]])
    # Parked vehicles get nothing.
    np.testing.assert_allclose(reward(result(), np.array([[True, False, False]]), cfg), [[-0.1, 0.0, 0.0]])


def test_approach_reward_matches_distance_to_sam_outside_the_zone(strike_path):
    """Straight-line mode: outside its zone the approach term is the paper's d_{t-1} - d_t to the SAM, in km."""
    task = RoleTask(
        load(strike_path), Role.DECOY, n=1, teammates="none", seed=0, reward_config=RewardConfig(around_radars=False)
    )
    task.reset()
    w = task.world
    d0 = w.sam_dist_m[0, 0]
    _, r, _ = task.advance(np.array([[0.0, 0.0]]))
    d1 = w.sam_dist_m[0, 0]
    assert r[0] == pytest.approx((d0 - d1) / KM - 0.1, abs=1e-9)


def test_approach_reward_measures_the_way_around_the_radars(strike_path):
    """Default mode: the approach term is the decrease of zone distance + detour (tssac_core.sim.routes)."""
    task = RoleTask(load(strike_path), Role.STRIKE, n=1, teammates="none", seed=0)
    task.reset()
    w = task.world
    before = w.zone_dist_m[0, 2] + task.detour_m[0]
    _, r, _ = task.advance(np.array([[0.0, 0.0]]))
    after = w.zone_dist_m[0, 2] + task.detour_m[0]
    assert r[0] == pytest.approx((before - after) / KM - 0.1, abs=1e-9)
    # The paper's mission has radars between the start and the SAM: the way around is longer.
    assert task.detour_m[0] > 1000.0


def test_teammates_alone_and_callable(strike_path):
    s = load(strike_path)
    alone = RoleTask(s, Role.DECOY, n=1, teammates="none", seed=0)
    alone.reset()
    assert alone.world.active[0].tolist() == [True, False, False]
    calls = []

    def straight(obs):
        calls.append(obs.shape)
        return np.zeros((obs.shape[0], 2))

    task = RoleTask(s, Role.STRIKE, n=2, teammates={"decoy": straight, "detect": "guidance"}, seed=0)
    task.reset()
    x0 = task.world.x_m.copy()
    task.step(np.zeros((2, 2)))
    assert calls == [(2, EXTENDED_SIZE)]
    assert task.world.active[0].tolist() == [True, True, True]
    assert (task.world.x_m != x0).all()
    with pytest.raises(ValueError, match="unknown role"):
        RoleTask(s, Role.STRIKE, teammates={"bomber": "guidance"})
    with pytest.raises(ValueError, match="must be 'guidance', None or a callable"):
        RoleTask(s, Role.STRIKE, teammates={"decoy": 3})


def test_guidance_team_completes_the_fixed_mission(strike_path):
    env = gym.make("tssac/Strike-v0", scenario=strike_path)
    obs, _ = env.reset(seed=0)
    # The strike UAV flown by hand: straight at the SAM, then circle inside R1.
    total_cost, steps = 0.0, 0
    from tssac_core.sim.guidance import Guidance

    g = Guidance()
    while True:
        action = g.actions(snapshot(env.unwrapped.task.world))[0, 2]
        obs, r, term, trunc, info = env.step(action.astype(np.float32))
        total_cost += info["cost"]
        steps += 1
        if term or trunc:
            break
    assert term and info["hit"] and total_cost == 0.0
    assert steps < 4000


def test_pilot_actions_are_held_for_their_repeat(strike_path):
    """A pilot trained with action_repeat K has its action held for K world steps."""
    s = load(strike_path)

    class Counting:
        action_repeat = 3

        def __init__(self):
            self.k = 0

        def __call__(self, obs):
            self.k += 1
            return np.full((obs.shape[0], 2), self.k / 10.0)

    pilot = Counting()
    task = RoleTask(s, Role.STRIKE, n=1, teammates={"decoy": pilot}, seed=0)
    task.reset()
    seen = []
    for _ in range(7):
        actions = task.team.actions(task.world, skip=task.j)
        seen.append(actions[0, 0, 0])
        task.world.step(actions)
    assert seen == pytest.approx([0.1, 0.1, 0.1, 0.2, 0.2, 0.2, 0.3])
    assert pilot.k == 3  # asked only at decision steps


def test_role_task_repeat_sums_reward_and_cost(strike_path):
    s = load(strike_path)
    a = RoleTask(s, Role.DECOY, n=1, teammates="none", seed=0)
    b = RoleTask(s, Role.DECOY, n=1, teammates="none", seed=0)
    a.reset(), b.reset()
    act = np.array([[0.2, 0.1]])
    held = a.step(act, repeat=5)
    total_r = sum(b.step(act).reward[0] for _ in range(5))
    assert held.reward[0] == pytest.approx(total_r)
    assert a.world.steps[0] == 5 and b.world.steps[0] == 5
    np.testing.assert_array_equal(a.world.x_m, b.world.x_m)


def test_unused_radar_slots_do_not_change_the_observation(strike_path):
    """A world with spare radar slots observes exactly what a world sized to the layout does."""
    from tssac_core.sim.observation import observe
    from tssac_core.sim.world import World

    s = load(strike_path)
    snug, roomy = World(s, 1), World(s, 1, max_radars=5)
    for w in (snug, roomy):
        w.reset([0], [s.layout])
    for j in range(3):
        np.testing.assert_array_equal(
            observe(snapshot(snug), j, ObservationMode.EXTENDED), observe(snapshot(roomy), j, ObservationMode.EXTENDED)
        )
    one = World(s, 1, max_radars=1)
    lay = s.layout
    one.reset([0], [type(lay)(lay.sam_km, lay.target_km, lay.radars[:1], lay.starts)])
    obs = observe(snapshot(one), 0, ObservationMode.EXTENDED)[0]
    np.testing.assert_array_equal(obs[14:20], [1.0, 1.0, 0.0, 1.0, 1.0, 0.0])  # missing radars: far, dead ahead
