"""``gym.make_vec("tssac/<Role>-v0", num_envs=N)``: N worlds of one role as a gymnasium ``VectorEnv`` on the batched
world (:class:`tssac_core.sim.role_task.RoleTask`), one array step for all N instead of N Python envs.

It is N copies of :class:`tssac_core.sim.env.UavRoleEnv` put side by side, to the bit: the same keyword arguments
(``scenario``, ``observation``, ``action_repeat``, ``teammates``, ``reward_config``), world ``i`` seeded as a single
env reset with ``seed + i`` (gymnasium's rule for vector seeds). Each info key comes with its ``_key`` mask, as
``SyncVectorEnv`` builds them. Finished worlds reset in one of gymnasium's two autoreset modes
(``autoreset_mode=``, in ``metadata["autoreset_mode"]``; https://farama.org/Vector-Autoreset-Mode):

- ``AutoresetMode.SAME_STEP`` (the default): in the step that ends it, ``obs`` holds the new episode's first
  observation, ``info["final_obs"]`` and ``info["final_info"]`` (masked by ``info["_final_obs"]``) the last of the
  old one.
- ``AutoresetMode.NEXT_STEP`` (gymnasium's own default; ``gym.make_vec(id, num_envs=N,
  autoreset_mode=AutoresetMode.NEXT_STEP)``): the step that ends it returns its last observation and info; the next
  step resets it (its action is ignored, reward 0, not terminated or truncated, the reset's observation and info).
  gymnasium's stateful vector wrappers (``NormalizeObservation``, ``NormalizeReward``) take only this mode.

tests/test_gym_faces.py holds it equal to ``SyncVectorEnv(..., autoreset_mode=...)`` of the single env, step for
step, in both modes. ``AutoresetMode.DISABLED`` is refused (ValueError).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from tssac_core.sim.env import DEFAULT_ACTION_REPEAT, DEFAULT_OBSERVATION, check_action_repeat
from tssac_core.sim.observation import ObservationMode, observation_bounds, observe
from tssac_core.sim.pilots import GUIDANCE
from tssac_core.sim.reward import RewardConfig
from tssac_core.sim.role_task import RoleTask, Teammates
from tssac_core.sim.scenario import DEFAULT_SCENARIO, Role, Scenario, load
from tssac_core.sim.world_state import snapshot

INFO_KEYS = ("cost", "radar_on", "identified", "hit", "task_done", "in_hazard")
"""The per-world info of :class:`tssac_core.sim.env.UavRoleEnv`, in its order."""


class RoleVectorEnv(gym.vector.VectorEnv):
    """N worlds of one role (module docstring); ``step`` takes actions (N, 2) in [-1, 1]."""

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.SAME_STEP}
    """The class's default; an instance's says its own ``autoreset_mode``."""

    def __init__(
        self,
        num_envs: int = 1,
        role: str | Role = Role.DECOY,
        scenario: str | Path | Scenario = DEFAULT_SCENARIO,
        observation: str | ObservationMode = DEFAULT_OBSERVATION,
        teammates: Teammates = GUIDANCE,
        reward_config: RewardConfig = RewardConfig(),
        action_repeat: int = DEFAULT_ACTION_REPEAT,
        autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP,
    ) -> None:
        mode = AutoresetMode(autoreset_mode)
        if mode not in (AutoresetMode.SAME_STEP, AutoresetMode.NEXT_STEP):
            raise ValueError(f"autoreset_mode must be SAME_STEP or NEXT_STEP, got {mode}")
        self.autoreset_mode = mode
        self.metadata = {**self.metadata, "autoreset_mode": mode}
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        self.scenario = scenario if isinstance(scenario, Scenario) else load(scenario)
        self.role = Role(role)
        self.mode = ObservationMode(observation)
        self.action_repeat = check_action_repeat(action_repeat)
        self.num_envs = num_envs
        self.task = RoleTask(self.scenario, self.role, num_envs, self.mode, teammates, reward_config=reward_config)
        low, high = observation_bounds(self.mode)
        self.single_observation_space = gym.spaces.Box(low, high, dtype=np.float32)
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._rngs: list[np.random.Generator] = [seeding.np_random(None)[0] for _ in range(num_envs)]
        self._needs_reset = True
        self._autoreset = np.zeros(num_envs, dtype=bool)
        """NEXT_STEP: the worlds that ended at the last step, reset at the next."""

    def reset(
        self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every world; ``seed`` S seeds world i with S + i (or a list gives each its own), as SyncVectorEnv."""
        if seed is None:
            seeds: Sequence[int | None] = [None] * self.num_envs
        elif isinstance(seed, int | np.integer):
            seeds = [int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"reset: {len(seeds)} seeds for {self.num_envs} envs")
        self._rngs = [seeding.np_random(s)[0] for s in seeds]
        obs = self.task.reset(rng=self._rngs)
        self._needs_reset = False
        self._autoreset = np.zeros(self.num_envs, dtype=bool)
        return obs.astype(np.float32), self._infos(np.ones(self.num_envs, dtype=bool))

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if self._needs_reset:
            raise RuntimeError("call reset() before step()")
        held = np.asarray(actions, dtype=np.float64).reshape(self.num_envs, 2)
        reward = np.zeros(self.num_envs)
        cost = np.zeros(self.num_envs)
        terminated = np.zeros(self.num_envs, dtype=bool)
        truncated = np.zeros(self.num_envs, dtype=bool)
        final_obs = np.full(self.num_envs, None, dtype=object)
        final_flags: dict[str, np.ndarray] = {}
        # NEXT_STEP: the worlds that ended at the last step sit out this one (World.step leaves a finished world: its
        # reward and cost are 0, it neither terminates nor truncates again), then start their next episode.
        resetting = self._autoreset
        for _ in range(self.action_repeat if not resetting.all() else 0):
            result, r, c = self.task.advance(held)
            reward += r  # a world that ended part-way flies no more: World.step leaves it, its reward and cost are 0
            cost += c
            newly = (result.terminated | result.truncated) & ~(terminated | truncated)
            terminated |= result.terminated
            truncated |= result.truncated
            if newly.any():  # its last observation and flags now: the world's mission flags still change after it
                self._keep_final(np.flatnonzero(newly), final_obs, final_flags)
            if (terminated | truncated | resetting).all():
                break
        ended = terminated | truncated
        if self.autoreset_mode is AutoresetMode.NEXT_STEP:
            return self._next_step(reward, cost, terminated, truncated, final_obs, final_flags)
        infos: dict[str, Any] = {}
        if ended.any():
            final = self._infos(ended, cost, final_flags)
            infos = {"final_obs": final_obs, "_final_obs": ended.copy(), "final_info": final, "_final_info": ended}
            obs = self.task.reset(np.flatnonzero(ended), self._rngs)
        else:
            obs = observe(snapshot(self.task.world), self.task.j, self.mode, self.task.obs_routes)
        infos.update(self._infos(np.ones(self.num_envs, dtype=bool), np.where(ended, 0.0, cost)))
        return obs.astype(np.float32), reward, terminated, truncated, infos

    def _next_step(
        self,
        reward: np.ndarray,
        cost: np.ndarray,
        terminated: np.ndarray,
        truncated: np.ndarray,
        final_obs: np.ndarray,
        final_flags: dict[str, np.ndarray],
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """The end of a NEXT_STEP step: reset the worlds that ended at the last step; a world that ended in this one
        shows its last observation and flags (those of the world step it ended at)."""
        resetting = self._autoreset
        if resetting.any():
            obs = self.task.reset(np.flatnonzero(resetting), self._rngs)
        else:
            obs = observe(snapshot(self.task.world), self.task.j, self.mode, self.task.obs_routes)
        obs = obs.astype(np.float32)
        ended = terminated | truncated
        flags = self._flags()
        for i in np.flatnonzero(ended):
            obs[i] = final_obs[i]
        for key, kept in final_flags.items():
            flags[key] = np.where(ended, kept, flags[key])
        self._autoreset = ended
        return obs, reward, terminated, truncated, self._infos(np.ones(self.num_envs, dtype=bool), cost, flags)

    def _flags(self) -> dict[str, np.ndarray]:
        """The mission flags of every world now, for the learning role: (N,) bool each."""
        w, j = self.task.world, self.task.j
        return {
            "radar_on": w.radar_on.copy(),
            "identified": w.identified.copy(),
            "hit": w.hit.copy(),
            "task_done": w.task_done[:, j].copy(),
            "in_hazard": w.in_hazard[:, j].copy(),
        }

    def _keep_final(self, idx: np.ndarray, final_obs: np.ndarray, final_flags: dict[str, np.ndarray]) -> None:
        """Record the last observation and flags of worlds ``idx``, which ended at this world step."""
        obs = observe(snapshot(self.task.world), self.task.j, self.mode, self.task.obs_routes).astype(np.float32)
        flags = self._flags()
        for i in idx:
            final_obs[i] = obs[i]
        for key, value in flags.items():
            kept = final_flags.setdefault(key, np.zeros(self.num_envs, dtype=bool))
            kept[idx] = value[idx]

    def _infos(
        self, mask: np.ndarray, cost: np.ndarray | None = None, flags: dict[str, np.ndarray] | None = None
    ) -> dict[str, Any]:
        """Each info key as an (N,) array with its ``_key`` mask (worlds outside ``mask`` hold zeros); ``flags``
        instead of the worlds' flags now."""
        values = {"cost": np.zeros(self.num_envs) if cost is None else cost.astype(np.float64)}
        values.update(flags if flags is not None else self._flags())
        infos: dict[str, Any] = {}
        for key in INFO_KEYS:
            value = np.where(mask, values[key], np.zeros((), dtype=values[key].dtype))
            infos[key], infos[f"_{key}"] = value, mask.copy()
        return infos
