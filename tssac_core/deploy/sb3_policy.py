"""A Stable-Baselines3 model file as a :class:`~tssac_core.deploy.policy_spec.PolicySpec`.

``from_sb3("model.zip", ...)`` reads what ``model.save("model.zip")`` wrote (any algorithm: PPO, A2C, SAC, TD3, ...)
with Stable-Baselines3's own reader, rebuilds the policy network from its saved class, arguments and weights, and
acts with ``policy.predict(obs, deterministic=True)``: the action SB3's ``model.predict(obs, deterministic=True)``
gives (clipped to the action space, or squashed and rescaled). The saved observation space is the env's it was trained
on: it names the observation (its shape and bounds are one mode's), and
:func:`~tssac_core.deploy.policy_spec.check_policy` checks it and the action space against the env's. The decision
interval is not in the file: state it (``decision_interval_s=``) or pass the env (``env=``).

A model trained behind ``VecNormalize`` is refused: its observation statistics live in a file of their own, and the
policy without them would be another controller.

The network of an MLP policy (``MlpPolicy``: PPO's and A2C's actor path, SAC's and TD3's actor) is kept as
:class:`~tssac_core.deploy.mlp_graph.Layer` s, so that :mod:`tssac_core.deploy.policy_export` can write it as an ONNX
actor. stable-baselines3 (the ``sb3`` extra) is imported when a model loads, never by importing this module.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tssac_core.deploy.any_policy import Stated, resolve
from tssac_core.deploy.mlp_graph import Layer, LayerKind, linear, torch_layers
from tssac_core.deploy.policy_spec import PolicyError, PolicySpec, SpaceBounds, first_line
from tssac_core.sim.observation import ObservationMode, observation_bounds
from tssac_core.sim.scenario import Role

INSTALL = "pip install -e '.[sb3]'"


def from_sb3(
    path: str | Path,
    observation: str | ObservationMode | None = None,
    decision_interval_s: float | None = None,
    env: Any = None,
    role: Role | str | None = None,
) -> PolicySpec:
    """The policy of a Stable-Baselines3 model file (module docstring); PolicyError (one line) for a file that is not
    one, a model trained behind VecNormalize, or what is not stated."""
    p = Path(path)
    if not p.is_file():
        raise PolicyError(f"{p}: Stable-Baselines3 model file not found")
    policy, data = read_model(p)
    obs_space = space_bounds(data.get("observation_space"), p, "observation")
    act_space = space_bounds(data.get("action_space"), p, "action")
    said = resolve(
        str(p), observation, decision_interval_s, env, role, Stated("its saved observation space", mode_of(obs_space))
    )
    assert said.observation is not None and said.decision_interval_s is not None

    def act(obs: np.ndarray) -> np.ndarray:
        actions, _ = policy.predict(obs, deterministic=True)
        return np.asarray(actions)

    return PolicySpec(
        act,
        said.observation,
        said.decision_interval_s,
        str(p),
        said.role,
        observation_space=obs_space,
        action_space=act_space,
        layers=policy_layers(policy),
        clip=not bool(getattr(policy, "squash_output", False)),
    )


def read_model(p: Path) -> tuple[Any, dict[str, Any]]:
    """(the policy network in eval mode, the saved data) of a model file."""
    try:
        from stable_baselines3.common.save_util import load_from_zip_file
    except ImportError:
        raise PolicyError(f"{p}: reading a Stable-Baselines3 model needs stable-baselines3 ({INSTALL})") from None
    try:
        data, params, _ = load_from_zip_file(p, device="cpu", print_system_info=False)
    except Exception as exc:  # zipfile, json, torch and pickle errors on a file that is not a model
        raise PolicyError(f"{p}: not a readable Stable-Baselines3 model ({first_line(exc)})") from None
    if data is None or params is None or "policy" not in params:
        raise PolicyError(f"{p}: not a Stable-Baselines3 model (no saved data or policy weights)")
    if data.get("_last_original_obs") is not None:
        raise PolicyError(
            f"{p}: trained behind VecNormalize, whose observation statistics are not in the model file: the policy "
            "without them would be another controller (train without VecNormalize to evaluate it here)"
        )
    policy_class = data.get("policy_class")
    if not isinstance(policy_class, type):
        raise PolicyError(f"{p}: its policy class could not be read back (saved by another Stable-Baselines3?)")
    try:
        policy = policy_class(
            data["observation_space"], data["action_space"], lambda _: 0.0, **(data.get("policy_kwargs") or {})
        )
        policy.load_state_dict(params["policy"])
    except Exception as exc:  # the saved class, arguments and weights must fit each other
        raise PolicyError(f"{p}: its policy network could not be rebuilt ({first_line(exc)})") from None
    policy.set_training_mode(False)
    return policy, data


def space_bounds(space: Any, p: Path, what: str) -> SpaceBounds:
    """A saved gymnasium Box as :class:`SpaceBounds`; PolicyError for another kind of space."""
    if type(space).__name__ != "Box" or not hasattr(space, "low"):
        raise PolicyError(f"{p}: trained on a {type(space).__name__} {what} space, not the env's Box")
    return SpaceBounds(tuple(space.shape), str(space.dtype), np.asarray(space.low), np.asarray(space.high))


def mode_of(space: SpaceBounds) -> ObservationMode | None:
    """The observation mode whose Box is ``space`` (shape and bounds), or None (another env's: the check says how)."""
    for mode in ObservationMode:
        low, high = observation_bounds(mode)
        if space.shape == low.shape and np.allclose(space.low, low) and np.allclose(space.high, high):
            return mode
    return None


def policy_layers(policy: Any) -> tuple[Layer, ...] | None:
    """The actor of an MLP policy as layers, up to the action before SB3's clip or squash: the actor-critic's
    (PPO, A2C) policy net and action net, SAC's latent net and mean then tanh, TD3's actor net; None for anything else
    (a CNN, gSDE, a recurrent policy)."""
    if getattr(policy, "use_sde", False):
        return None
    extractor = getattr(policy, "mlp_extractor", None)
    if extractor is not None and hasattr(policy, "action_net"):  # ActorCriticPolicy: PPO, A2C
        if not flat_features(policy):
            return None
        pi = torch_layers(extractor.policy_net)
        net = policy.action_net
        if pi is None or type(net).__name__ != "Linear" or getattr(policy, "squash_output", False):
            return None
        return (*pi, linear(net.weight, net.bias))
    actor = getattr(policy, "actor", None)
    if actor is None or not flat_features(actor):
        return None
    if hasattr(actor, "latent_pi") and hasattr(actor, "mu"):  # SAC: tanh(mu(latent_pi(obs)))
        latent, mu = torch_layers(actor.latent_pi), torch_layers(actor.mu)
        if latent is None or mu is None:
            return None
        return (*latent, *mu, Layer(LayerKind.TANH))
    if hasattr(actor, "mu"):  # TD3, DDPG: mu ends with its tanh
        return torch_layers(actor.mu)
    return None


def flat_features(module: Any) -> bool:
    """Whether ``module``'s features extractor only flattens (the MLP policies' on a vector observation)."""
    extractor = getattr(module, "features_extractor", None)
    return extractor is not None and type(extractor).__name__ == "FlattenExtractor"
