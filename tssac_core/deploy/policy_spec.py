"""A policy with what it was trained on stated, and its check against the env of the role it is to fly.

:class:`PolicySpec` holds a policy's actions (a batch of observations (n, d) float32 -> actions (n, 2)), the observation
it was trained on, its decision interval in seconds, and what its file keeps of its training (role, spaces, network).
The loaders that make one are in :mod:`tssac_core.deploy.any_policy` (and :mod:`tssac_core.deploy.sb3_policy`).

:func:`check_policy` checks a spec against the env of the role it is to fly, before the first mission: the role it was
trained as, the decision interval as whole world steps, the observation and action spaces it was trained on where
known (shape, dtype and bounds), and one call on a batch of observations from the env's observation space (the
action batch's shape, finite values). Each mismatch is one :class:`PolicyError` line. It returns the
:class:`StatedPolicy` the batched world's pilots fly (:class:`tssac_core.sim.pilots.PolicyPilot` reads its
``observation_mode`` and ``action_repeat``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from tssac_core.common.errors import MAX_ACTION_REPEAT, InputError
from tssac_core.deploy.mlp_graph import Layer
from tssac_core.sim.observation import ObservationMode, observation_bounds
from tssac_core.sim.scenario import Role

ACTION_SIZE = 2
"""The action [omega, u] (the env's ``Box(-1, 1, (2,))``)."""
ACTOR_STEP_S = 0.1
"""The world step a TSSAC actor's ``action_repeat`` counts (its ONNX metadata, ``.npz``, ``.pt``): every shipped
scenario's ``dt_s``."""
PROBE_BATCH = 4
"""Observations in :func:`check_policy`'s probe call."""

Act = Callable[[np.ndarray], np.ndarray]


class PolicyError(InputError):
    """A policy that does not fit the env it is to fly, or is not stated enough to fly; ``str()`` is one line."""


@dataclass(frozen=True)
class SpaceBounds:
    """A Box space a policy was trained on: shape, dtype and bounds (as its framework saved it)."""

    shape: tuple[int, ...]
    dtype: str
    low: np.ndarray
    high: np.ndarray


@dataclass(frozen=True, eq=False)
class PolicySpec:
    """A policy with what it was trained on stated (module docstring)."""

    act: Act
    """A batch of observations (n, d) float32 -> actions (n, 2)."""
    observation_mode: ObservationMode
    decision_interval_s: float
    name: str
    """What the results and errors call it (a file's path, a function's name)."""
    role: Role | None = None
    """The role it was trained as, when known (it flies that role only)."""
    observation_space: SpaceBounds | None = None
    """The observation space it was trained on, when its file says (checked against the env's)."""
    action_space: SpaceBounds | None = None
    """The action space it was trained on, when its file says."""
    layers: tuple[Layer, ...] | None = None
    """Its network as MLP layers, when it is one (what :mod:`tssac_core.deploy.policy_export` writes as ONNX)."""
    onnx_model: bytes | None = None
    """Its ONNX model with the metadata stated, when it came from one."""
    clip: bool = True
    """Whether its raw actions may leave [-1, 1] (an ONNX export then clips them, as the world does)."""


class StatedPolicy:
    """A checked spec as a pilot flies it: ``obs (n, d) -> actions (n, 2)`` float64, with the ``observation_mode`` and
    ``action_repeat`` (world steps) the batched world's :class:`~tssac_core.sim.pilots.PolicyPilot` reads."""

    def __init__(self, spec: PolicySpec, action_repeat: int) -> None:
        self.spec = spec
        self.name = spec.name
        self.observation_mode = spec.observation_mode
        self.action_repeat = action_repeat

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return np.asarray(self.spec.act(np.asarray(obs, dtype=np.float32)), dtype=np.float64)


def first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text.splitlines()[0]}" if text else type(exc).__name__


# ------------------------------------------------------------------------------ the check before the first mission


def steps_per_decision(interval_s: float, dt_s: float, name: str) -> int:
    """The decision interval as whole world steps of ``dt_s``; PolicyError if it is not one."""
    steps = round(interval_s / dt_s)
    if steps < 1 or not math.isclose(steps * dt_s, interval_s, rel_tol=1e-6, abs_tol=1e-9):
        raise PolicyError(
            f"{name}: a decision interval of {interval_s:g} s is not a whole number of the world's {dt_s:g} s steps"
        )
    if steps > MAX_ACTION_REPEAT:
        raise PolicyError(f"{name}: a decision interval of {interval_s:g} s is longer than any mission")
    return steps


def check_policy(spec: PolicySpec, role: Role, dt_s: float) -> StatedPolicy:
    """``spec`` checked against the env of ``role`` in a world of ``dt_s`` steps (module docstring): the pilot that
    flies it, or PolicyError (one line) for the first thing that does not fit."""
    name = spec.name
    if spec.role is not None and spec.role is not role:
        raise PolicyError(f"{name}: trained as the {spec.role.value} UAV, asked to fly the {role.value}")
    repeat = steps_per_decision(spec.decision_interval_s, dt_s, name)
    mode = spec.observation_mode
    low, high = observation_bounds(mode)
    if spec.observation_space is not None:
        check_space(name, "observation", spec.observation_space, low, high, f"the '{mode.value}' observation")
    if spec.action_space is not None:
        check_space(
            name,
            "action",
            spec.action_space,
            -np.ones(ACTION_SIZE, np.float32),
            np.ones(ACTION_SIZE, np.float32),
            "the env's action Box(-1, 1, (2,))",
        )
    probe(spec, low, high)
    return StatedPolicy(spec, repeat)


def check_space(name: str, what: str, trained: SpaceBounds, low: np.ndarray, high: np.ndarray, env_text: str) -> None:
    """The space a policy was trained on against the env's: shape, dtype and bounds."""
    if trained.shape != low.shape:
        size = trained.shape[0] if len(trained.shape) == 1 else trained.shape
        raise PolicyError(
            f"{name}: trained on {what}s of shape {trained.shape}, {env_text} has {low.shape} ({size} vs "
            f"{low.shape[0]} values)"
        )
    if not np.issubdtype(np.dtype(trained.dtype), np.floating):
        raise PolicyError(f"{name}: trained on {trained.dtype} {what}s, {env_text} is float32")
    for bound, mine, env in (("lower", trained.low, low), ("upper", trained.high, high)):
        differ = np.flatnonzero(~np.isclose(np.asarray(mine, np.float64), env.astype(np.float64)))
        if differ.size:
            i = int(differ[0])
            raise PolicyError(
                f"{name}: trained on {what}s whose {bound} bound at entry {i} is {float(mine[i]):g}, {env_text}'s is "
                f"{float(env[i]):g} (trained on another env)"
            )


def probe(spec: PolicySpec, low: np.ndarray, high: np.ndarray) -> None:
    """One call on :data:`PROBE_BATCH` observations drawn from the env's observation space: the actions must come
    back as a finite (n, 2) batch."""
    obs = np.random.default_rng(0).uniform(low, high, (PROBE_BATCH, low.size)).astype(np.float32)
    where = f"a batch of {PROBE_BATCH} '{spec.observation_mode.value}' observations ({low.size} values each)"
    try:
        out = np.asarray(spec.act(obs))
    except PolicyError:
        raise
    except Exception as exc:  # a foreign policy fails in its own way (a shape error in a matmul, a dtype, ...)
        raise PolicyError(f"{spec.name}: fails on {where}: {first_line(exc)}") from None
    if out.shape != (PROBE_BATCH, ACTION_SIZE):
        raise PolicyError(
            f"{spec.name}: returns shape {out.shape} for {where}, not the actions ({PROBE_BATCH}, {ACTION_SIZE})"
        )
    if not np.issubdtype(out.dtype, np.number) or not np.all(np.isfinite(out)):
        raise PolicyError(f"{spec.name}: returns actions that are not finite numbers for {where}")
