"""The constrained MDP of one UAV role: a batched task for training, and a ``gymnasium.Env`` over it.

:class:`RoleTask` runs N worlds for one learning role (decoy, detect or strike) with its teammates
flown by given pilots (:mod:`tssac_core.sim.team`), resetting finished worlds itself; the training loop
uses it directly. :class:`UavRoleEnv` is the same task with N = 1 behind the gymnasium API, registered
as ``tssac/Decoy-v0``, ``tssac/Detect-v0`` and ``tssac/Strike-v0`` when this module is imported
(``gym.make("tssac_core.sim.env:tssac/Detect-v0", ...)`` imports it; keyword arguments: ``scenario=``,
``observation=``, ``teammates=``).
"""

from __future__ import annotations

import pickle
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from tssac_core.sim.hard_layouts import HardLayouts, LayoutSource
from tssac_core.sim.observation import ObservationMode, observation_bounds, observe
from tssac_core.sim.reward import RewardConfig, reward
from tssac_core.sim.routes import RouteConfig, RouteMap
from tssac_core.sim.scenario import DEFAULT_SCENARIO, ROLES, Role, Scenario, load
from tssac_core.sim.team import GUIDANCE, Pilot, Team, check_pilot
from tssac_core.sim.world import StepResult, World

Teammates = str | Mapping[str, Pilot] | None


def resolve_pilots(role: Role, teammates: Teammates) -> list[Pilot]:
    """Pilots for the three vehicles; the learner's own slot is ``"learner"``.

    ``teammates`` is ``"guidance"`` (all teammates flown by the guidance controller), ``"none"`` or
    None (the learner flies alone, as the decoy is trained), or a mapping role name -> pilot; roles
    missing from the mapping are parked.
    """
    if teammates == GUIDANCE:
        table: Mapping[str, Pilot] = {r.value: GUIDANCE for r in ROLES}
    elif teammates is None or teammates == "none":
        table = {}
    elif isinstance(teammates, Mapping):
        table = teammates
        for name in table:
            if name not in [r.value for r in ROLES]:
                raise ValueError(f"teammates: unknown role {name!r}")
    else:
        raise ValueError(f"teammates must be 'guidance', 'none' or a mapping role -> pilot, got {teammates!r}")
    pilots: list[Pilot] = []
    for r in ROLES:
        if r is role:
            pilots.append("learner")
        else:
            pilot = table.get(r.value)
            check_pilot(pilot, r.value)
            pilots.append(pilot)
    return pilots


@dataclass
class TaskStep:
    """One step of a RoleTask, every array (N, ...)."""

    obs: np.ndarray
    """Observation after the step; for worlds that ended, the first one of the new episode."""
    final_obs: np.ndarray
    """Observation after the step before any reset (what the replay buffer stores as s')."""
    reward: np.ndarray
    cost: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    episode_return: np.ndarray
    """For worlds that ended this step: the episode's return (else 0)."""
    episode_cost: np.ndarray
    """For worlds that ended: the episode's sum of the learner's cost (with the task's cost margin)."""
    episode_hazard_cost: np.ndarray
    """For worlds that ended: the learner's eq. 11 hazard cost (steps inside a radar), margin or not."""
    episode_success: np.ndarray
    """For worlds that ended: the mission succeeded (target hit)."""
    episode_task: np.ndarray
    """For worlds that ended: the learning role's task was completed (eq. 9)."""


class RoleTask:
    """N worlds in which one role learns; finished worlds are reset with a new layout."""

    def __init__(
        self,
        scenario: Scenario,
        role: Role,
        n: int = 1,
        observation: ObservationMode = ObservationMode.EXTENDED,
        teammates: Teammates = GUIDANCE,
        seed: int | None = None,
        reward_config: RewardConfig = RewardConfig(),
        cost_margin_m: float = 0.0,
        hard_layouts: HardLayouts = HardLayouts(),
    ) -> None:
        self.scenario = scenario
        self.layouts = LayoutSource(scenario, hard_layouts)
        """Where new episodes' layouts come from (hard ones more often, when asked: tssac_core.sim.hard_layouts)."""
        self.role = role
        self.j = role.index
        self.mode = observation
        self.pilots = resolve_pilots(role, teammates)
        self.active = tuple(p is not None for p in self.pilots)
        self.reward_config = reward_config
        self.cost_margin_m = cost_margin_m
        """The learner's cost counts steps within this distance of a radar's disk (0: eq. 11 exactly); the
        mission's own figures (``world.cost_total``, ``episode_hazard_cost``) stay eq. 11."""
        self.routes = RouteMap(reward_config.route)
        """Route fields of the reward's approach term (the observation's own, in route mode, have the default
        margins)."""
        self.obs_routes = self.routes if reward_config.route == RouteConfig() else RouteMap()
        self.world = World(scenario, n)
        self.team = Team(self.pilots, observation)
        self.rng = np.random.default_rng(seed)
        self.ep_return = np.zeros(n)
        self.ep_cost = np.zeros(n)
        self.detour_m = np.zeros(n)
        """The learner's detour now, (N,) (reward term r_approach), kept current by reset and advance; the
        teammates' detours are not measured (their rewards are nobody's concern here)."""

    @property
    def n(self) -> int:
        return self.world.n

    def reset(
        self, index: Sequence[int] | np.ndarray | None = None, rng: np.random.Generator | None = None
    ) -> np.ndarray:
        """Reset worlds (all if ``index`` is None) and return every world's observation."""
        idx = np.arange(self.n) if index is None else np.asarray(index)
        gen = rng if rng is not None else self.rng
        self.world.reset(idx, [self.layouts.draw(gen) for _ in idx], self.active)
        self.ep_return[idx] = 0.0
        self.ep_cost[idx] = 0.0
        self._measure_detours()
        return observe(self.world, self.j, self.mode, self.obs_routes)

    def snapshot(self) -> bytes:
        """The task's state (worlds, layout generator, running episode sums) for a resume file."""
        return pickle.dumps((self.world, self.rng, self.ep_return, self.ep_cost))

    def restore(self, snapshot: bytes) -> None:
        """Continue from a :meth:`snapshot` (the pilots stay those this task was built with)."""
        self.world, self.rng, self.ep_return, self.ep_cost = pickle.loads(snapshot)
        self._measure_detours()

    def _measure_detours(self) -> None:
        if self.reward_config.around_radars:
            self.detour_m = self.routes.detour_m(self.world, self.j)

    def advance(self, action: np.ndarray) -> tuple[StepResult, np.ndarray, np.ndarray]:
        """Step all worlds with the learner's ``action`` (N, 2); no reset. Returns (result, reward, cost)."""
        actions = self.team.actions(self.world, skip=self.j)
        actions[:, self.j] = action
        detour_prev = self.detour_m
        result = self.world.step(actions)
        moving = result.moving
        self._measure_detours()
        r = reward(result, moving, self.reward_config, detour_prev, self.detour_m, vehicle=self.j)
        cost = result.cost[:, self.j]
        if self.cost_margin_m > 0:
            cost = (self.world.near_radar(self.cost_margin_m)[:, self.j] & moving[:, self.j]).astype(np.float64)
        # Afresh, not in place: an in-place update of a one-element array (N = 1) takes numpy's slow path.
        self.ep_return = self.ep_return + r
        self.ep_cost = self.ep_cost + cost
        return result, r, cost

    def step(self, action: np.ndarray, rng: np.random.Generator | None = None, repeat: int = 1) -> TaskStep:
        """Step all worlds with the learner's ``action`` (N, 2) held for ``repeat`` world steps; reset those that end.

        Rewards and costs are summed over the held steps (a world that ends part-way adds nothing more).
        """
        result, r, cost = self.advance(action)
        terminated, truncated = result.terminated.copy(), result.truncated.copy()
        for _ in range(repeat - 1):
            result, r_k, cost_k = self.advance(action)
            r, cost = r + r_k, cost + cost_k
            terminated |= result.terminated
            truncated |= result.truncated
        final_obs = observe(self.world, self.j, self.mode, self.obs_routes)
        ended = terminated | truncated
        ep_return = np.where(ended, self.ep_return, 0.0)
        ep_cost = np.where(ended, self.ep_cost, 0.0)
        ep_hazard = np.where(ended, self.world.cost_total[:, self.j], 0.0)
        success = ended & self.world.hit
        task = ended & self.world.task_done[:, self.j]
        obs = final_obs
        if ended.any():
            obs = self.reset(np.flatnonzero(ended), rng)
        return TaskStep(obs, final_obs, r, cost, terminated, truncated, ep_return, ep_cost, ep_hazard, success, task)


class UavRoleEnv(gym.Env):
    """One UAV of the air-to-surface mission as a constrained MDP (paper section 3.3).

    **Action** (eq. 8), ``Box(-1, 1, (2,))``: [omega, u], scaled to the vehicle's turn-rate and
    acceleration limits (scenario file), e.g. +-5 deg/s and +-10 m/s^2.

    **Observation**: ``observation="extended"`` (default, 22 values), ``"route"`` (24: extended plus the
    direction of the way around the radars; what training uses by default) or ``"paper"`` (eq. 7, 5 values);
    the table is in :mod:`tssac_core.sim.observation`.

    **Reward** (eq. 10, Table 2, plus a zone-holding term and a leaving penalty): see
    :mod:`tssac_core.sim.reward`.

    **Cost** (eq. 11): ``info["cost"]`` is 1 for a step inside any radar's disk, else 0; the budget is
    the scenario's ``cost_limit`` (C = 3) per episode.

    **Start**: a layout from the scenario (fixed, or drawn from its ``random:`` ranges with
    ``self.np_random``); speeds at their initial values.

    **Termination**: the target is hit (mission success), or any flying UAV leaves the area.
    **Truncation**: the scenario's episode cap (4,000 steps of 0.1 s).

    ``teammates``: ``"guidance"`` (default), ``"none"``, or a mapping role name -> pilot
    (``"guidance"``, a callable obs -> action, or None to park that UAV).
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        role: str | Role = Role.DECOY,
        scenario: str | Path | Scenario = DEFAULT_SCENARIO,
        observation: str | ObservationMode = ObservationMode.EXTENDED,
        teammates: Teammates = GUIDANCE,
        reward_config: RewardConfig = RewardConfig(),
    ) -> None:
        super().__init__()
        self.scenario = scenario if isinstance(scenario, Scenario) else load(scenario)
        self.role = Role(role)
        self.mode = ObservationMode(observation)
        self.task = RoleTask(self.scenario, self.role, 1, self.mode, teammates, reward_config=reward_config)
        low, high = observation_bounds(self.mode)
        self.observation_space = gym.spaces.Box(low, high, dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self._needs_reset = True

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        obs = self.task.reset(rng=self.np_random)
        self._needs_reset = False
        return obs[0], self._info()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._needs_reset:
            raise RuntimeError("call reset() before step() (the episode has ended)")
        # Not cast here: the assignment into the world's float64 actions makes the same floats in fewer calls.
        result, r, cost = self.task.advance(np.asarray(action).reshape(1, 2))
        terminated, truncated = bool(result.terminated[0]), bool(result.truncated[0])
        self._needs_reset = terminated or truncated
        info = self._info()
        info["cost"] = float(cost[0])
        return (
            observe(self.task.world, self.task.j, self.mode, self.task.obs_routes)[0],
            float(r[0]),
            terminated,
            truncated,
            info,
        )

    def _info(self) -> dict[str, Any]:
        w = self.task.world
        return {
            "cost": 0.0,
            "radar_on": bool(w.radar_on[0]),
            "identified": bool(w.identified[0]),
            "hit": bool(w.hit[0]),
            "task_done": bool(w.task_done[0, self.task.j]),
            "in_hazard": bool(w.in_hazard[0, self.task.j]),
        }


for _role in ROLES:
    _id = f"tssac/{_role.value.capitalize()}-v0"
    if _id not in gym.envs.registry:
        gym.register(id=_id, entry_point="tssac_core.sim.env:UavRoleEnv", kwargs={"role": _role.value})
