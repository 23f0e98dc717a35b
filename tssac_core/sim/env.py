"""The gymnasium face of one UAV role's constrained MDP: :class:`UavRoleEnv`, and the registered ids.

Importing this module registers ``tssac/Decoy-v0``, ``tssac/Detect-v0`` and ``tssac/Strike-v0``
(``gym.make("tssac_core.sim.env:tssac/Detect-v0", ...)`` imports it), and their Safety-Gymnasium forms
``tssac/SafeDecoy-v0``, ``tssac/SafeDetect-v0``, ``tssac/SafeStrike-v0`` (:class:`SafeUavRoleEnv`).
Keyword arguments: ``scenario=``, ``observation=`` (default ``route``), ``action_repeat=`` (default 10: one decision
per simulated second), ``teammates=``. The defaults are what the shipped team (``models/tssac/config.json``) was
trained with, so a shipped actor flies here as it was trained. ``gym.make_vec(id, num_envs=N)`` builds the batched
:class:`tssac_core.sim.vector_env.RoleVectorEnv` (one world array for all N) rather than N copies of this env.
The batched task itself is :class:`tssac_core.sim.role_task.RoleTask` (re-exported here).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from tssac_core.sim.observation import ObservationMode, observation_bounds, observe
from tssac_core.sim.pilots import GUIDANCE
from tssac_core.sim.reward import RewardConfig
from tssac_core.sim.role_task import RoleTask, TaskStep, Teammates, resolve_pilots
from tssac_core.sim.scenario import DEFAULT_SCENARIO, ROLES, Layout, Radar, Role, Scenario, load
from tssac_core.sim.world_state import snapshot

__all__ = [
    "DEFAULT_ACTION_REPEAT",
    "RoleTask",
    "SafeUavRoleEnv",
    "TaskStep",
    "Teammates",
    "UavRoleEnv",
    "resolve_pilots",
]

DEFAULT_OBSERVATION = ObservationMode.ROUTE
"""The shipped team's observation (models/tssac/config.json)."""
DEFAULT_ACTION_REPEAT = 10
"""The shipped team's decision interval in 0.1 s world steps (models/tssac/config.json)."""


def check_action_repeat(action_repeat: int) -> int:
    if isinstance(action_repeat, bool) or not isinstance(action_repeat, int | np.integer) or action_repeat < 1:
        raise ValueError(f"action_repeat must be a positive integer (world steps per decision), got {action_repeat!r}")
    return int(action_repeat)


def role_info(task: RoleTask, i: int) -> dict[str, Any]:
    """The info of world ``i`` of ``task`` for its learning role (mission flags; ``cost`` 0 until a step sets it)."""
    w = task.world
    return {
        "cost": 0.0,
        "radar_on": bool(w.radar_on[i]),
        "identified": bool(w.identified[i]),
        "hit": bool(w.hit[i]),
        "task_done": bool(w.task_done[i, task.j]),
        "in_hazard": bool(w.in_hazard[i, task.j]),
    }


class UavRoleEnv(gym.Env):
    """One UAV of the air-to-surface mission as a constrained MDP (paper section 3.3).

    **Action** (eq. 8), ``Box(-1, 1, (2,))``: [omega, u], scaled to the vehicle's turn-rate and
    acceleration limits (scenario file), e.g. +-5 deg/s and +-10 m/s^2; held for ``action_repeat`` world steps of
    0.1 s (default 10: one decision per second, as the shipped team decides).

    **Observation**: ``observation="route"`` (default, 24 values: extended plus the direction of the way around the
    radars; what the shipped team and training use), ``"extended"`` (22) or ``"paper"`` (eq. 7, 5 values); the table
    is in :mod:`tssac_core.sim.observation`.

    **Reward** (eq. 10, Table 2, plus a zone-holding term and a leaving penalty): see
    :mod:`tssac_core.sim.reward`.

    **Reward and cost of a step** are summed over its ``action_repeat`` world steps (a step that ends the episode
    part-way stops there).

    **Cost** (eq. 11): ``info["cost"]`` counts the world steps inside any radar's disk (0 or 1 per world step);
    the budget is the scenario's ``cost_limit`` (C = 3) per episode. :meth:`safe_step` returns it in the tuple,
    Safety-Gymnasium's way: ``obs, reward, cost, terminated, truncated, info``.

    **Start**: a layout from the scenario (fixed, or drawn from its ``random:`` ranges with
    ``self.np_random``); speeds at their initial values.

    **Termination**: the target is hit (mission success), or any flying UAV leaves the area.
    **Truncation**: the scenario's episode cap (4,000 world steps of 0.1 s, 400 steps at ``action_repeat`` 10).

    ``teammates``: ``"guidance"`` (default), ``"none"``, or a mapping role name -> pilot
    (``"guidance"``, a callable obs -> action such as a shipped actor,
    ``tssac_core.deploy.numpy_actor.load_policy(path)``, or None to park that UAV); roles missing from a mapping
    are parked.

    **Rendering** (``render_mode=``): ``"rgb_array"``: :meth:`render` returns the world now as an (H, W, 3) uint8
    frame: the area, the radars' coverage, the SAM's rings, the target and each flying UAV's track since the reset,
    drawn by :mod:`tssac_core.sim.drawing` with matplotlib's Agg into a buffer (matplotlib is imported at the first
    frame). ``"human"``: the same frame shown in a pyplot window, without blocking, at every step; with a
    non-interactive backend (Agg, e.g. a headless machine) nothing visible is drawn and nothing fails.
    ``metadata["render_fps"]`` is one frame per decision in simulated time (1 at ``action_repeat`` 10).

    **Seeding**: ``reset(seed=S)`` flies the layout of ``evaluate --seed S``'s mission 0 (mission k of seed S is
    ``reset(seed=S + k)``), so an episode here and a mission there can be compared layout for layout.
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 1}
    """``render_fps`` here is the default's; an instance's is 1 / (dt_s * action_repeat)."""

    def __init__(
        self,
        role: str | Role = Role.DECOY,
        scenario: str | Path | Scenario = DEFAULT_SCENARIO,
        observation: str | ObservationMode = DEFAULT_OBSERVATION,
        teammates: Teammates = GUIDANCE,
        reward_config: RewardConfig = RewardConfig(),
        action_repeat: int = DEFAULT_ACTION_REPEAT,
        render_mode: str | None = None,
    ) -> None:
        super().__init__()
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self.scenario = scenario if isinstance(scenario, Scenario) else load(scenario)
        self.role = Role(role)
        self.mode = ObservationMode(observation)
        self.action_repeat = check_action_repeat(action_repeat)
        self.task = RoleTask(self.scenario, self.role, 1, self.mode, teammates, reward_config=reward_config)
        low, high = observation_bounds(self.mode)
        self.observation_space = gym.spaces.Box(low, high, dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.metadata = {**self.metadata, "render_fps": 1.0 / (self.scenario.dt_s * self.action_repeat)}
        self._needs_reset = True
        self._tracks_m: list[np.ndarray] | None = None
        """With a render mode: every world step's positions since the reset, (2, 3) each."""
        self._canvas: Any = None
        self._window: Any = None

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        obs = self.task.reset(rng=self.np_random)
        self._needs_reset = False
        if self.render_mode is not None:
            self._tracks_m = [self.task.world.xy_m[:, 0].copy()]
            self._show()
        return obs[0], self._info()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._needs_reset:
            raise RuntimeError("call reset() before step() (the episode has ended)")
        # Not cast here: the assignment into the world's float64 actions makes the same floats in fewer calls.
        held = np.asarray(action).reshape(1, 2)
        total_r = total_c = 0.0
        for _ in range(self.action_repeat):
            result, r, cost = self.task.advance(held)
            if self._tracks_m is not None:
                self._tracks_m.append(self.task.world.xy_m[:, 0].copy())
            total_r += float(r[0])
            total_c += float(cost[0])
            terminated, truncated = bool(result.terminated[0]), bool(result.truncated[0])
            if terminated or truncated:
                break
        self._needs_reset = terminated or truncated
        info = self._info()
        info["cost"] = total_c
        self._show()
        return (
            observe(snapshot(self.task.world), self.task.j, self.mode, self.task.obs_routes)[0],
            total_r,
            terminated,
            truncated,
            info,
        )

    def safe_step(self, action: np.ndarray) -> tuple[np.ndarray, float, float, bool, bool, dict[str, Any]]:
        """Safety-Gymnasium's step: ``obs, reward, cost, terminated, truncated, info`` (the cost also stays in
        ``info["cost"]``)."""
        obs, r, terminated, truncated, info = self.step(action)
        return obs, r, float(info["cost"]), terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """``rgb_array``: the frame now (class docstring); ``human``: shows it, returns None; no render mode: a warning
        (gymnasium's), None."""
        if self.render_mode is None:
            spec_id = self.spec.id if self.spec is not None else "tssac/Decoy-v0"
            gym.logger.warn(
                "You are calling render method without specifying any render mode. You can specify the render_mode at "
                f'initialization, e.g. gym.make("{spec_id}", render_mode="rgb_array")'
            )
            return None
        frame = self._frame()
        if self.render_mode == "human":
            self._show_in_window(frame)
            return None
        return frame

    def close(self) -> None:
        """Release the frame's figure and the window."""
        self._canvas = None
        if self._window is not None:
            import matplotlib.pyplot as plt

            plt.close(self._window[0])
            self._window = None
        super().close()

    def _show(self) -> None:
        if self.render_mode == "human":
            self.render()

    def _frame(self) -> np.ndarray:
        """The world now drawn with Agg into a buffer: (H, W, 3) uint8."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        from tssac_core.sim.drawing import LEGEND_BESIDE, draw_layout, draw_tracks

        if self._canvas is None:  # no pyplot: the figure is this env's, whatever backend pyplot has
            self._canvas = FigureCanvasAgg(Figure(figsize=(9.8, 5.3), dpi=80))
        fig = self._canvas.figure
        fig.clear()
        ax = fig.add_subplot()
        w, s = self.task.world, self.scenario
        radars = tuple(
            Radar((float(p[0]) / 1000, float(p[1]) / 1000), float(r) / 1000)
            for p, r in zip(w.radar_m[0], w.radar_r_m[0])
            if r > 0
        )
        layout = Layout(tuple(w.sam_m[0] / 1000), tuple(w.target_m[0] / 1000), radars, {})
        r = s.ranges
        draw_layout(ax, layout, (r.strike_launch_km, r.detect_km, r.sam_launch_km, r.sam_detect_km), s.area_km)
        tracks = np.stack(self._tracks_m or [w.xy_m[:, 0]]) / 1000  # (T, 2, 3) km
        draw_tracks(
            ax,
            {
                role.value: list(zip(tracks[:, 0, k], tracks[:, 1, k]))
                for k, role in enumerate(ROLES)
                if self.task.active[k]
            },
        )
        ax.set_title(f"{self.role.value} env: t = {(len(tracks) - 1) * s.dt_s:.0f} s")
        ax.legend(**LEGEND_BESIDE)
        fig.tight_layout()
        self._canvas.draw()
        return np.asarray(self._canvas.buffer_rgba())[..., :3].copy()

    def _show_in_window(self, frame: np.ndarray) -> None:
        import matplotlib.pyplot as plt
        from matplotlib.backends import BackendFilter, backend_registry

        if plt.get_backend().lower() not in backend_registry.list_builtin(BackendFilter.INTERACTIVE):
            return  # Agg or another non-interactive backend (a headless machine): nothing to show, nothing fails
        if self._window is None:
            fig, ax = plt.subplots()
            ax.set_axis_off()
            self._window = (fig, ax.imshow(frame))
            plt.show(block=False)
        else:
            self._window[1].set_data(frame)
        self._window[0].canvas.draw_idle()
        self._window[0].canvas.flush_events()

    def _info(self) -> dict[str, Any]:
        return role_info(self.task, 0)


class SafeUavRoleEnv(gym.Wrapper[np.ndarray, np.ndarray, np.ndarray, np.ndarray]):
    """Safety-Gymnasium's form of :class:`UavRoleEnv` (``tssac/Safe<Role>-v0``): ``step`` returns
    ``obs, reward, cost, terminated, truncated, info``, as Safety-Gymnasium's envs do (its
    ``safety_gymnasium.builder.Builder.step``); everything else is the wrapped env's. The keyword arguments are
    :class:`UavRoleEnv`'s. The cost also stays in ``info["cost"]``.

    gymnasium's own checker and wrappers expect the 5-tuple, so the ids are registered without the passive checker
    (``disable_env_checker``); the wrapped env still refuses a step before ``reset``.
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(UavRoleEnv(**kwargs))

    # tuple[Any, ...]: the one return type that both gymnasium's Env.step (a 5-tuple) admits and these six items
    # fit; the items' types are UavRoleEnv.safe_step's.
    def step(self, action: np.ndarray) -> tuple[Any, ...]:
        env = self.env.unwrapped
        assert isinstance(env, UavRoleEnv)
        return env.safe_step(action)


def env_id(role: Role | str) -> str:
    """The registered id of a role's env: ``tssac/Decoy-v0``, ``tssac/Detect-v0``, ``tssac/Strike-v0``."""
    return f"tssac/{Role(role).value.capitalize()}-v0"


def safe_env_id(role: Role | str) -> str:
    """The registered id of a role's Safety-Gymnasium form: ``tssac/SafeDecoy-v0`` and so on."""
    return f"tssac/Safe{Role(role).value.capitalize()}-v0"


for _role in ROLES:
    if env_id(_role) not in gym.envs.registry:
        gym.register(
            id=env_id(_role),
            entry_point="tssac_core.sim.env:UavRoleEnv",
            vector_entry_point="tssac_core.sim.vector_env:RoleVectorEnv",
            kwargs={"role": _role.value},
        )
    if safe_env_id(_role) not in gym.envs.registry:
        gym.register(
            id=safe_env_id(_role),
            entry_point="tssac_core.sim.env:SafeUavRoleEnv",
            kwargs={"role": _role.value},
            disable_env_checker=True,
        )
