"""Any policy, trained in any framework, as the evaluator flies it: a :class:`PolicySpec`.

A policy flies a role here once three things about it are known, and a spec holds all three:

- its actions: ``act(obs)``, a batch of observations (n, d) float32 -> actions (n, 2), [omega, u] in [-1, 1]
  (values outside are clipped, as the env clips them);
- the observation it was trained on (``paper``, ``extended`` or ``route``: :mod:`tssac_core.sim.observation`);
- its decision interval, in seconds: how long each action is held (the env's ``action_repeat`` world steps of
  ``dt_s``: 1 s at the env's defaults, as the shipped team decides).

The loaders take the last two as arguments (``observation=``, ``decision_interval_s=``), from the env it was trained on
(``env=``: a ``tssac/<Role>-v0`` env, its vector form or a Stable-Baselines3 VecEnv of it, which knows both and the
role), or from the file where the file says them (a TSSAC ONNX actor's metadata; a Stable-Baselines3 model's saved
observation space names the observation). What is said twice must agree; what is said nowhere is asked for, in one line.
A policy is never flown in a default it did not state: that would be a different controller.

- :func:`from_callable`: a numpy function or object, batch in and batch out (``batched=False``: one observation
  (d,) -> one action (2,), called row by row);
- :func:`from_torch`: a ``torch.nn.Module`` (or a function on tensors) mapping the observation tensor (n, d) to the
  deterministic action (n, 2): what CleanRL's and OmniSafe's actors are (README, "Evaluating any policy");
- :func:`from_onnx`: an ONNX graph, observation (n, d) -> action (n, 2) in [-1, 1]
  (:mod:`tssac_core.deploy.onnx_actor`'s form; the metadata it lacks is stated here and written into it);
- :func:`tssac_core.deploy.sb3_policy.from_sb3`: a Stable-Baselines3 model file (``model.save(path)``).

The spec and its check against the role's env before the first mission (:func:`check_policy`: one
:class:`PolicyError` line per mismatch) are in :mod:`tssac_core.deploy.policy_spec`, re-exported here.
``tssac_core.evaluate.evaluate_policy`` is the entry point that checks and flies the missions;
:mod:`tssac_core.deploy.policy_export` writes a spec as an ONNX actor that ``fly`` and the companion fly.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tssac_core.deploy.policy_spec import (
    ACTION_SIZE,
    ACTOR_STEP_S,
    Act,
    PolicyError,
    PolicySpec,
    SpaceBounds,
    StatedPolicy,
    check_policy,
    first_line,
    steps_per_decision,
)
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.scenario import Role

__all__ = [
    "PolicyError",
    "PolicySpec",
    "SpaceBounds",
    "Stated",
    "StatedPolicy",
    "check_policy",
    "from_callable",
    "from_onnx",
    "from_torch",
    "load_torch_module",
    "resolve",
]

# ------------------------------------------------------------------------------ what is stated, and by whom


@dataclass(frozen=True)
class Stated:
    """What one source says of a policy (None: it says nothing of that)."""

    source: str
    observation: ObservationMode | None = None
    decision_interval_s: float | None = None
    role: Role | None = None


def env_says(env: Any) -> Stated:
    """What the env a policy was trained on says: its observation, decision interval and role (PolicyError for an env
    that is not a ``tssac/<Role>-v0`` env, its vector form, or a Stable-Baselines3 VecEnv of one)."""
    inner = env.envs[0] if hasattr(env, "envs") and not hasattr(env, "task") else env  # an SB3 DummyVecEnv
    base = getattr(inner, "unwrapped", inner)
    try:
        return Stated(
            "the env it was trained on",
            ObservationMode(base.mode),
            float(base.action_repeat) * float(base.scenario.dt_s),
            Role(base.role),
        )
    except (AttributeError, ValueError, TypeError):
        raise PolicyError(
            f"env={type(env).__name__}: not a tssac/<Role>-v0 env (gym.make or gym.make_vec of one): state "
            "observation= and decision_interval_s= instead"
        ) from None


def stated_by_caller(observation: str | ObservationMode | None, decision_interval_s: float | None) -> Stated:
    """The caller's own statements, checked: a known observation mode, a positive finite interval."""
    mode = None
    if observation is not None:
        try:
            mode = ObservationMode(observation)
        except ValueError:
            modes = ", ".join(m.value for m in ObservationMode)
            raise PolicyError(f"observation {observation!r} is not one of {modes}") from None
    interval = None
    if decision_interval_s is not None:
        if isinstance(decision_interval_s, bool) or not isinstance(decision_interval_s, int | float):
            raise PolicyError(f"decision_interval_s must be a number of seconds, got {decision_interval_s!r}")
        interval = float(decision_interval_s)
        if not (math.isfinite(interval) and interval > 0):
            raise PolicyError(f"decision_interval_s must be a positive number of seconds, got {decision_interval_s!r}")
    return Stated("you", mode, interval, None)


def agree(name: str, sources: list[Stated]) -> Stated:
    """The one observation, interval and role the ``sources`` state (each must be stated by one at least, and all
    that state one must agree): PolicyError naming the two that differ, or what nobody stated."""

    def pick(field: str, what: str) -> Any:
        said = [(s.source, getattr(s, field)) for s in sources if getattr(s, field) is not None]
        for source, value in said[1:]:
            first_source, first = said[0]
            if (not math.isclose(value, first, rel_tol=1e-9)) if field == "decision_interval_s" else value != first:
                raise PolicyError(f"{name}: {first_source} said {what} {show(first)}, {source} says {show(value)}")
        return said[0][1] if said else None

    mode = pick("observation", "observation")
    interval = pick("decision_interval_s", "decision interval")
    role = pick("role", "role")
    missing = [
        text
        for text, value in (
            ("observation= (route, extended or paper)", mode),
            ("decision_interval_s= (seconds per decision: 1.0 for the env's default action_repeat=10)", interval),
        )
        if value is None
    ]
    if missing:
        raise PolicyError(
            f"{name}: state the {' and '.join(missing)} of the env it was trained on, or pass that env (env=)"
        )
    return Stated("", mode, interval, role)


def show(value: Any) -> str:
    if isinstance(value, ObservationMode | Role):
        return repr(value.value)
    if isinstance(value, float):
        return f"{value:g} s"
    return repr(value)


def resolve(
    name: str,
    observation: str | ObservationMode | None,
    decision_interval_s: float | None,
    env: Any,
    role: Role | str | None = None,
    file: Stated | None = None,
) -> Stated:
    """What a loader's arguments, the env and the file say together (:func:`agree`)."""
    caller = stated_by_caller(observation, decision_interval_s)
    sources = [Stated(caller.source, caller.observation, caller.decision_interval_s, _role(role))]
    if env is not None:
        sources.append(env_says(env))
    if file is not None:
        sources.append(file)
    return agree(name, sources)


def _role(role: Role | str | None) -> Role | None:
    if role is None:
        return None
    try:
        return Role(role)
    except ValueError:
        raise PolicyError(f"role {role!r} is not decoy, detect or strike") from None


# ------------------------------------------------------------------------------ loaders


def from_callable(
    fn: Act,
    observation: str | ObservationMode | None = None,
    decision_interval_s: float | None = None,
    env: Any = None,
    role: Role | str | None = None,
    batched: bool = True,
    name: str | None = None,
) -> PolicySpec:
    """A numpy policy: ``fn(obs (n, d)) -> actions (n, 2)``, or with ``batched=False`` ``fn(obs (d,)) -> (2,)`` called
    once per observation. A shipped actor (``load_policy(path)``) states its own observation and interval."""
    if not callable(fn):
        raise PolicyError(f"the policy must be callable (obs -> action), got {type(fn).__name__}")
    label = name or getattr(fn, "__name__", None) or type(fn).__name__
    own_mode, own_repeat, own_role = (getattr(fn, key, None) for key in ("observation_mode", "action_repeat", "role"))
    try:
        file = Stated(
            f"{label} itself",
            None if own_mode is None else ObservationMode(own_mode),
            None if own_repeat is None else float(own_repeat) * ACTOR_STEP_S,
            own_role if isinstance(own_role, Role) else None,
        )
    except (ValueError, TypeError):
        raise PolicyError(
            f"{label}: its observation_mode {own_mode!r} or action_repeat {own_repeat!r} is not one (route, extended "
            "or paper; world steps of 0.1 s)"
        ) from None
    said = resolve(label, observation, decision_interval_s, env, role, file)
    act = fn if batched else _row_by_row(fn)
    assert said.observation is not None and said.decision_interval_s is not None
    return PolicySpec(act, said.observation, said.decision_interval_s, label, said.role)


def _row_by_row(fn: Act) -> Act:
    def act(obs: np.ndarray) -> np.ndarray:
        return np.array([np.asarray(fn(row), dtype=np.float64).reshape(ACTION_SIZE) for row in obs]).reshape(
            len(obs), ACTION_SIZE
        )

    return act


def from_torch(
    module: Callable[..., Any],
    observation: str | ObservationMode | None = None,
    decision_interval_s: float | None = None,
    env: Any = None,
    role: Role | str | None = None,
    name: str | None = None,
) -> PolicySpec:
    """A torch policy: ``module(obs tensor (n, d) float32) -> deterministic action tensor (n, 2)``, run under
    ``torch.no_grad()`` on the CPU (a module is put in eval mode). CleanRL's continuous PPO ``agent.actor_mean``, an
    OmniSafe on-policy actor's ``actor.mean``, or any function of that form (README, "Evaluating any policy"). An
    ``nn.Sequential`` of Linear, Tanh and ReLU layers can also be written as an ONNX actor."""
    import torch

    from tssac_core.deploy.mlp_graph import torch_layers

    if not callable(module):
        raise PolicyError(f"the policy must be a torch module or function, got {type(module).__name__}")
    label = name or getattr(module, "__name__", None) or type(module).__name__
    said = resolve(label, observation, decision_interval_s, env, role)
    if isinstance(module, torch.nn.Module):
        module.eval()

    def act(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            out = module(torch.as_tensor(obs, dtype=torch.float32))
        if isinstance(out, tuple | list):
            raise PolicyError(
                f"{label}: returns {len(out)} values, not the action tensor (n, {ACTION_SIZE}): pass the module or "
                "function that gives the deterministic action (README, 'Evaluating any policy')"
            )
        return np.asarray(out.detach().cpu().numpy() if isinstance(out, torch.Tensor) else out)

    layers = torch_layers(module) if isinstance(module, torch.nn.Module) else None
    assert said.observation is not None and said.decision_interval_s is not None
    return PolicySpec(act, said.observation, said.decision_interval_s, label, said.role, layers=layers)


def load_torch_module(path: str | Path) -> Any:
    """A whole ``torch.nn.Module`` saved with ``torch.save(module, path)`` (unpickled: load only files you trust)."""
    import torch

    p = Path(path)
    if not p.is_file():
        raise PolicyError(f"{p}: torch module file not found")
    try:
        module = torch.load(p, map_location="cpu", weights_only=False)
    except Exception as exc:  # torch and pickle raise many kinds on a foreign or corrupt file
        raise PolicyError(f"{p}: not a loadable torch module ({first_line(exc)})") from None
    if not isinstance(module, torch.nn.Module):
        raise PolicyError(
            f"{p}: holds a {type(module).__name__}, not a torch.nn.Module (save the actor itself: torch.save(actor, "
            "path))"
        )
    return module


def from_onnx(
    path: str | Path,
    observation: str | ObservationMode | None = None,
    decision_interval_s: float | None = None,
    env: Any = None,
    role: Role | str | None = None,
) -> PolicySpec:
    """An ONNX actor: observation (n, d) float32 -> action (n, 2) in [-1, 1]. A TSSAC actor (``export --format onnx``)
    states its role, observation and interval in its metadata; a graph from elsewhere gets them from here, written
    into its metadata (flown with onnxruntime: the ``onnx`` extra)."""
    from tssac_core.deploy.onnx_actor import INSTALL, OnnxPolicy, read_metadata

    p = Path(path)
    if not p.is_file():
        raise PolicyError(f"{p}: ONNX file not found")
    try:
        import onnx
    except ImportError:
        raise PolicyError(f"{p}: reading an ONNX policy needs the onnx package ({INSTALL})") from None
    try:
        model = onnx.load_from_string(p.read_bytes())
    except Exception as exc:  # protobuf's DecodeError and others on a file that is not a model
        raise PolicyError(f"{p}: not a readable ONNX model ({first_line(exc)})") from None
    props = {entry.key: entry.value for entry in model.metadata_props}
    file = None
    if all(key in props for key in ("role", "observation_mode", "action_repeat")):
        file_role, file_mode, repeat = read_metadata(props, str(p))
        file = Stated("its metadata", file_mode, repeat * ACTOR_STEP_S, file_role)
    said = resolve(str(p), observation, decision_interval_s, env, role, file)
    if said.role is None:
        raise PolicyError(f"{p}: say which role it flies (role=decoy, detect or strike): its metadata does not")
    assert said.observation is not None and said.decision_interval_s is not None
    repeat = steps_per_decision(said.decision_interval_s, ACTOR_STEP_S, str(p))
    props.update({"role": said.role.value, "observation_mode": said.observation.value, "action_repeat": str(repeat)})
    onnx.helper.set_model_props(model, props)
    data = model.SerializeToString()
    actor = OnnxPolicy(data, str(p), said.role)
    return PolicySpec(
        actor.act, said.observation, said.decision_interval_s, str(p), said.role, onnx_model=data, clip=False
    )
