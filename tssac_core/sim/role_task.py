"""The constrained MDP of one UAV role over N worlds at once: :class:`RoleTask` (numpy only, no gymnasium).

:class:`RoleTask` runs N worlds for one learning role (decoy, detect or strike) with its teammates flown by
given pilots (:mod:`tssac_core.sim.team`), resetting finished worlds itself. The training loop uses it directly;
the gymnasium env and vector env (:mod:`tssac_core.sim.env`, :mod:`tssac_core.sim.vector_env`) and the OmniSafe
adapter (:mod:`tssac_core.train.omnisafe_env`) are faces over it.
"""

from __future__ import annotations

import pickle
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from tssac_core.assurance.ground_loiter import LoiterBound
from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.sim.hard_layouts import HardLayouts, LayoutSource
from tssac_core.sim.observation import ObservationMode, observe
from tssac_core.sim.pilots import GUIDANCE, LEARNER, PilotSpec, check_pilot, decision_interval
from tssac_core.sim.reward import RewardConfig, reward
from tssac_core.sim.routes import RouteConfig, RouteMap
from tssac_core.sim.scenario import ROLES, Role, Scenario
from tssac_core.sim.team import Team
from tssac_core.sim.varied_airframes import AirframeVariation, VariedAirframes
from tssac_core.sim.world import StepResult, World
from tssac_core.sim.world_monitor import WorldMonitor
from tssac_core.sim.world_state import snapshot

Teammates = str | Mapping[str, PilotSpec] | None


def resolve_pilots(role: Role, teammates: Teammates) -> list[PilotSpec]:
    """Pilots for the three vehicles; the learner's own slot is ``"learner"``.

    ``teammates`` is ``"guidance"`` (all teammates flown by the guidance controller), ``"none"`` or
    None (the learner flies alone, as the decoy is trained), or a mapping role name -> pilot; roles
    missing from the mapping are parked.
    """
    if teammates == GUIDANCE:
        table: Mapping[str, PilotSpec] = {r.value: GUIDANCE for r in ROLES}
    elif teammates is None or teammates == "none":
        table = {}
    elif isinstance(teammates, Mapping):
        table = teammates
        for name in table:
            if name not in [r.value for r in ROLES]:
                raise ValueError(f"teammates: unknown role {name!r}")
    else:
        raise ValueError(f"teammates must be 'guidance', 'none' or a mapping role -> pilot, got {teammates!r}")
    pilots: list[PilotSpec] = []
    for r in ROLES:
        if r is role:
            pilots.append(LEARNER)
        else:
            pilot = table.get(r.value)
            check_pilot(pilot, r.value)
            pilots.append(pilot)
    return pilots


@dataclass(frozen=True)
class MonitorInTraining:
    """The runtime-assurance monitor flying in the training worlds (:class:`~tssac_core.sim.world_monitor.WorldMonitor`,
    off unless asked for): every UAV, the learner's teammates too, flies through it as it would in a deployment, with
    the world's true state, predicting with each vehicle's varied airframe where the task has them. A world step it
    flies something other than the learner's proposal (its backup, or its adjusted action) costs the learner 1, as a
    step in a radar does: the Lagrangian then teaches a team that leaves the monitor room to prove its backups, so
    that a monitored deployment loses little to its interventions (issue 58). Without that cost
    (``costs_overrule`` False) the monitor is a shield in the learner's world: the learner meets what its proposals
    lead to where the monitor turns them away (a gap it refuses, a backup's turn) and learns from the reward what
    to do next, its cost only the hazard's."""

    shield: ShieldConfig
    learner_repeat: int
    """World steps between the learner's decisions (the training's action repeat)."""
    loiter: LoiterBound | None = None
    """In wind, the backups end in the ground loiter this bounds (needs the task's varied airframes)."""
    costs_overrule: bool = True
    """A world step the monitor flies instead of the learner costs the learner 1."""


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
        airframes: AirframeVariation | None = None,
        monitor: MonitorInTraining | None = None,
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
        self.airframes = VariedAirframes(airframes, self.world) if airframes is not None else None
        """Varied airframes (tssac_core.sim.varied_airframes), or None: eq. 5-6 exactly."""
        self.monitor = None if monitor is None else self._monitor(monitor)
        """The monitor every UAV flies through (:class:`MonitorInTraining`), or None: the actions as proposed."""
        self.costs_overrule = monitor is not None and monitor.costs_overrule
        self.ep_return = np.zeros(n)
        self.ep_cost = np.zeros(n)
        self.detour_m = np.zeros(n)
        """The learner's detour now, (N,) (reward term r_approach), kept current by reset and advance; the
        teammates' detours are not measured (their rewards are nobody's concern here)."""

    @property
    def n(self) -> int:
        return self.world.n

    def _monitor(self, monitor: MonitorInTraining) -> WorldMonitor:
        if monitor.loiter is not None and self.airframes is None:
            raise ValueError("the monitor's ground loiter is bounded for varied airframes: train on them too")
        repeats = [monitor.learner_repeat if p == LEARNER else decision_interval(p) for p in self.pilots]
        return WorldMonitor(self.world, repeats, monitor.shield, self.airframes, monitor.loiter)

    def reset(
        self,
        index: Sequence[int] | np.ndarray | None = None,
        rng: np.random.Generator | Sequence[np.random.Generator] | None = None,
    ) -> np.ndarray:
        """Reset worlds (all if ``index`` is None) and return every world's observation. ``rng``: where the new
        layouts come from (default the task's own generator); a sequence gives world ``i`` its own, ``rng[i]``
        (what the gymnasium vector env does, so that each world draws as a single env seeded alike would)."""
        idx = np.arange(self.n) if index is None else np.asarray(index)
        if rng is None or isinstance(rng, np.random.Generator):
            gen = rng if rng is not None else self.rng
            layouts = [self.layouts.draw(gen) for _ in idx]
            self.world.reset(idx, layouts, self.active)
            if self.airframes is not None:
                self.airframes.reset(idx, gen)
        else:
            layouts = [self.layouts.draw(rng[int(i)]) for i in idx]
            self.world.reset(idx, layouts, self.active)
            for i in idx if self.airframes is not None else ():
                self.airframes.reset(np.array([i]), rng[int(i)])  # type: ignore[union-attr]
        if self.monitor is not None:
            self.monitor.reset(idx)
        self.ep_return[idx] = 0.0
        self.ep_cost[idx] = 0.0
        self._measure_detours()
        return observe(snapshot(self.world), self.j, self.mode, self.obs_routes)

    def state(self) -> bytes:
        """The task's state (worlds, layout generator, running episode sums) for a resume file, as the learners'
        ``state()``."""
        state = (self.world, self.rng, self.ep_return, self.ep_cost)
        # Varied airframes add their draws and lag state, a monitor its memory; without them the state is what it was
        # before they existed.
        if self.monitor is not None:
            return pickle.dumps((*state, self.airframes, self.monitor))
        return pickle.dumps(state if self.airframes is None else (*state, self.airframes))

    def restore(self, state: bytes) -> None:
        """Continue from a :meth:`state` (the pilots stay those this task was built with)."""
        saved = pickle.loads(state)
        self.world, self.rng, self.ep_return, self.ep_cost = saved[:4]
        self.airframes = saved[4] if len(saved) > 4 else None  # states written before varied airframes: none
        if self.monitor is not None:
            if len(saved) < 6:
                raise ValueError("a resume state without the monitor's memory, for a task that flies the monitor")
            self.monitor = saved[5]
        self._measure_detours()

    def _measure_detours(self) -> None:
        if self.reward_config.around_radars:
            self.detour_m = self.routes.detour_m(snapshot(self.world), self.j)

    def advance(self, action: np.ndarray) -> tuple[StepResult, np.ndarray, np.ndarray]:
        """Step all worlds with the learner's ``action`` (N, 2); no reset. Returns (result, reward, cost)."""
        actions = self.team.actions(self.world, skip=self.j)
        actions[:, self.j] = action
        if self.monitor is not None:
            actions = self.monitor.actions(self.world, actions)
        if self.airframes is not None:
            actions = self.airframes.shape(actions, self.rng)
        detour_prev = self.detour_m
        result = self.world.step(actions)
        moving = result.moving
        self._measure_detours()
        r = reward(result, moving, self.reward_config, detour_prev, self.detour_m, vehicle=self.j)
        cost = result.cost[:, self.j]
        if self.cost_margin_m > 0:
            cost = (self.world.near_radar(self.cost_margin_m)[:, self.j] & moving[:, self.j]).astype(np.float64)
        if self.monitor is not None and self.costs_overrule:  # a step the monitor flies instead of the learner
            cost = np.maximum(cost, self.monitor.overruled[:, self.j] & moving[:, self.j])
        # Afresh, not in place: an in-place update of a one-element array (N = 1) takes numpy's slow path.
        self.ep_return = self.ep_return + r
        self.ep_cost = self.ep_cost + cost
        return result, r, cost

    def step(
        self,
        action: np.ndarray,
        rng: np.random.Generator | Sequence[np.random.Generator] | None = None,
        repeat: int = 1,
    ) -> TaskStep:
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
        final_obs = observe(snapshot(self.world), self.j, self.mode, self.obs_routes)
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
