"""OmniSafe's face of one UAV role: a CMDP in OmniSafe's env registry (``TssacDecoy-v0``, ``TssacDetect-v0``,
``TssacStrike-v0``), on the batched world (:class:`tssac_core.sim.role_task.RoleTask`).

Importing this module registers the class with ``omnisafe.envs.core.env_register``; then
``omnisafe.Agent("PPOLag", "TssacDetect-v0", custom_cfgs=...)`` trains the role (README, "OmniSafe"). OmniSafe
0.5.0 pins gymnasium 0.28.1, so it lives in its own environment (``python benchmarks/omnisafe_env.py`` builds it and
prints its interpreter; this package on ``PYTHONPATH``): this module uses nothing of gymnasium but ``spaces.Box`` and
nothing of the project's gymnasium env, and runs under both versions (benchmarks/omnisafe_train.py runs it there).

What OmniSafe passes as ``env_cfgs`` (all optional; the defaults are the shipped team's settings):

    scenario        scenario file (default scenarios/random.yaml: a new random layout every episode)
    observation     route (default), extended or paper
    action_repeat   world steps of 0.1 s per decision (default 10)
    teammates       "guidance" (default), "none", or a models directory whose actors fly ``teammate_roles``
    teammate_roles  with a models directory: the roles its actors fly (default: the roles before this one, as
                    the curriculum trains; e.g. ["decoy"] beside the detect UAV); the others are parked
    layout_seed     layouts come from generators seeded layout_seed + i for world i (default: OmniSafe's seed)
    cost_margin_km  the cost counts world steps within this distance of a radar (default 0: eq. 11 exactly); our
                    own training command's default is 1 (``--cost-margin-km``, TrainConfig.cost_margin_km)
    leaving_terminates
                    false (default): only a hit is ``terminated``; leaving the area and the episode cap are
                    ``truncated``, so OmniSafe's critics bootstrap through them exactly as ours do
                    (docs/decisions.md, "Leaving the area ends the episode, but the critics bootstrap through it").
                    true: leaving is ``terminated`` too, a future of zero; then leaving is a way out of the step
                    penalty, and OmniSafe's CPO and PPOLag learn to leave (benchmarks/crosscheck/README.md)

Reward and cost of a step are summed over its ``action_repeat`` world steps; cost is eq. 11's (steps inside a
radar), or with ``cost_margin_km`` the tightened cost our learners constrain. OmniSafe reads ``terminated`` as no
future and bootstraps a ``truncated`` end from ``final_observation``. Finished worlds are reset in the same step
(``need_auto_reset_wrapper`` False): ``info["final_observation"]`` holds their last observation, as OmniSafe's
AutoReset wrapper would. The episode cap truncates.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch
from gymnasium import spaces
from omnisafe.envs.core import CMDP, env_register

from tssac_core.deploy.numpy_actor import team_pilots
from tssac_core.sim.observation import ObservationMode, observation_bounds, observe
from tssac_core.sim.role_task import RoleTask, Teammates
from tssac_core.sim.scenario import DEFAULT_SCENARIO, ROLES, Role, load
from tssac_core.sim.world_state import snapshot

ENV_IDS = {f"Tssac{role.value.capitalize()}-v0": role for role in ROLES}
"""OmniSafe env id -> the learning role."""


def teammates_from(role: Role, teammates: str, teammate_roles: list[str] | None) -> Teammates:
    """``env_cfgs``' teammates as pilots: the guidance controller, nobody, or the actors of a models directory."""
    if teammates in ("guidance", "none"):
        return teammates
    models = Path(teammates)
    if not models.is_dir():
        raise ValueError(f"teammates must be 'guidance', 'none' or a models directory, got {teammates!r}")
    roles = teammate_roles if teammate_roles is not None else [r.value for r in ROLES[: role.index]]
    if role.value in roles:
        raise ValueError(f"teammate_roles: {role.value} is the learning role")
    return team_pilots(models, roles)


@env_register
class TssacRoleEnv(CMDP):
    """One role's constrained MDP over ``num_envs`` worlds at once (module docstring)."""

    _support_envs: ClassVar[list[str]] = list(ENV_IDS)
    need_auto_reset_wrapper = False
    need_time_limit_wrapper = False

    def __init__(
        self,
        env_id: str,
        num_envs: int = 1,
        device: torch.device | str = "cpu",
        scenario: str = str(DEFAULT_SCENARIO),
        observation: str = ObservationMode.ROUTE.value,
        action_repeat: int = 10,
        teammates: str = "guidance",
        teammate_roles: list[str] | None = None,
        layout_seed: int | None = None,
        cost_margin_km: float = 0.0,
        leaving_terminates: bool = False,
        **kwargs: Any,
    ) -> None:
        super().__init__(env_id)
        if kwargs:
            raise ValueError(f"{env_id}: unknown env_cfgs {', '.join(sorted(kwargs))}")
        if action_repeat < 1:
            raise ValueError(f"action_repeat must be >= 1, got {action_repeat}")
        if cost_margin_km < 0:
            raise ValueError(f"cost_margin_km must be >= 0, got {cost_margin_km}")
        self.role = ENV_IDS[env_id]
        self._num_envs = num_envs
        self._device = torch.device(device)
        self.scenario = load(scenario)
        self.mode = ObservationMode(observation)
        self.action_repeat = action_repeat
        self.leaving_terminates = bool(leaving_terminates)
        self.layout_seed = layout_seed
        pilots = teammates_from(self.role, teammates, teammate_roles)
        self.task = RoleTask(
            self.scenario, self.role, num_envs, self.mode, pilots, cost_margin_m=cost_margin_km * 1000.0
        )
        low, high = observation_bounds(self.mode)
        self._observation_space = spaces.Box(low, high, dtype=np.float32)
        self._action_space = spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self._metadata: dict[str, Any] = {}
        self._rngs = [np.random.default_rng(None) for _ in range(num_envs)]

    @property
    def max_episode_steps(self) -> int:
        """Decisions per episode at most: the scenario's cap over the decision interval."""
        return -(-self.scenario.episode_steps // self.action_repeat)

    def set_seed(self, seed: int) -> None:
        base = self.layout_seed if self.layout_seed is not None else seed
        self._rngs = [np.random.default_rng(base + i) for i in range(self._num_envs)]

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[torch.Tensor, dict[str, Any]]:
        if seed is not None:
            self.set_seed(seed)
        obs = self.task.reset(rng=self._rngs)
        return self._out(obs), {}

    def step(
        self, action: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, dict[str, Any]]:
        held = action.detach().cpu().numpy().astype(np.float64).reshape(self._num_envs, 2)
        n = self._num_envs
        reward, cost = np.zeros(n), np.zeros(n)
        terminated, truncated = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
        final_obs = np.zeros((n, self.mode.size))
        for _ in range(self.action_repeat):
            result, r, c = self.task.advance(held)
            reward += r
            cost += c
            newly = (result.terminated | result.truncated) & ~(terminated | truncated)
            terminated |= result.terminated
            truncated |= result.truncated
            if newly.any():
                final_obs[newly] = observe(snapshot(self.task.world), self.task.j, self.mode, self.task.obs_routes)[
                    newly
                ]
            if (terminated | truncated).all():
                break
        ended = terminated | truncated
        if not self.leaving_terminates:
            # Only a hit ends the future; leaving (and the cap) bootstrap, as in our learners (module docstring).
            terminated = terminated & self.task.world.hit
            truncated = ended & ~terminated
        info: dict[str, Any] = {}
        if ended.any():
            obs = self.task.reset(np.flatnonzero(ended), self._rngs)
            info["final_observation"] = self._out(np.where(ended[:, None], final_obs, obs))
        else:
            obs = observe(snapshot(self.task.world), self.task.j, self.mode, self.task.obs_routes)
        return (
            self._out(obs),
            self._out(reward),
            self._out(cost),
            self._out(terminated),
            self._out(truncated),
            info,
        )

    def _out(self, array: np.ndarray) -> torch.Tensor:
        """As a tensor on the device: float32 (bool for flags), without the world axis for a single world (OmniSafe
        adds it back with its Unsqueeze wrapper)."""
        dtype = torch.bool if array.dtype == np.bool_ else torch.float32
        tensor = torch.as_tensor(np.ascontiguousarray(array), dtype=dtype, device=self._device)
        return tensor[0] if self._num_envs == 1 else tensor

    def render(self) -> Any:
        return None

    def close(self) -> None:
        return None
