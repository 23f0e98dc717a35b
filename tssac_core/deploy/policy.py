"""The deployment face: load a trained role's checkpoint and ``act(observation) -> action``.

A role checkpoint (``decoy.pt``, ``detect.pt``, ``strike.pt``, written by ``tssac_core.train``) holds
the actor's weights and what is needed to check that it fits where it is used: role, algorithm,
observation mode and size, the scenario's digest, package versions, and the full learner state (for
transfer to the next role). Anything that does not fit raises :class:`CheckpointError`, whose message
is one line.
"""

from __future__ import annotations

import io
import platform
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tssac_core.algos.networks import SquashedGaussianActor
from tssac_core.algos.onpolicy.ppo import CpoState, PpoState
from tssac_core.algos.sac_lagrangian import SacState
from tssac_core.common.errors import CheckpointError, check_action_repeat
from tssac_core.common.files import replace_durably
from tssac_core.deploy.actor_meta import CheckpointFields
from tssac_core.deploy.manifest import check_models, warn_once
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.scenario import ROLES, Role

FORMAT = "tssac-role-checkpoint"
FORMAT_VERSION = 1


@dataclass(frozen=True)
class CheckpointInfo:
    """What a role checkpoint says about itself."""

    role: Role
    algo: str
    observation_mode: ObservationMode
    obs_dim: int
    act_dim: int
    hidden_sizes: tuple[int, ...]
    scenario_digest: str
    versions: dict[str, str]
    metrics: dict[str, float]
    action_repeat: int = 1
    """The decision interval it was trained with: hold each action for this many 0.1 s steps."""

    def fields(self) -> CheckpointFields:
        """As plain JSON values: what a checkpoint (and an exported actor) stores beside the weights."""
        return {
            "role": self.role.value,
            "algo": str(self.algo),  # a plain string: a pickled enum would name a module of the package
            "observation_mode": self.observation_mode.value,
            "obs_dim": self.obs_dim,
            "act_dim": self.act_dim,
            "hidden_sizes": list(self.hidden_sizes),
            "scenario_digest": self.scenario_digest,
            "versions": self.versions,
            "metrics": self.metrics,
            "action_repeat": self.action_repeat,
        }


def package_versions() -> dict[str, str]:
    import gymnasium

    from tssac_core import __version__

    return {
        "tssac": __version__,
        "torch": torch.__version__,
        "numpy": np.__version__,
        "gymnasium": gymnasium.__version__,
        "python": platform.python_version(),
    }


def save_role_checkpoint(
    path: str | Path,
    info: CheckpointInfo,
    actor_state: dict[str, torch.Tensor],
    learner_state: SacState | PpoState | CpoState | None,
) -> None:
    """Write a role checkpoint atomically (a crash never leaves a half-written file)."""
    payload = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        **info.fields(),
        "actor": actor_state,
        "learner": learner_state,
    }
    torch_save_atomic(payload, path)


def torch_save_atomic(obj: Any, path: str | Path) -> None:
    """torch.save to a temporary file, then rename durably (tssac_core.common.files): a crash never leaves a
    half-written file."""
    target = Path(path)
    tmp = target.with_name(target.name + ".tmp")
    torch.save(obj, tmp)
    replace_durably(tmp, target)


def read_checkpoint(path: str | Path) -> dict[str, Any]:
    """The raw checkpoint dict, or CheckpointError for a missing or unreadable file."""
    p = Path(path)
    if not p.is_file():
        raise CheckpointError(f"{p}: checkpoint not found")
    try:
        data = torch.load(io.BytesIO(p.read_bytes()), map_location="cpu", weights_only=False)
    except Exception as exc:  # torch raises many kinds on a corrupt file
        raise CheckpointError(f"{p}: not a readable checkpoint ({type(exc).__name__})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise CheckpointError(f"{p}: not a TSSAC role checkpoint")
    if data.get("format_version") != FORMAT_VERSION:
        raise CheckpointError(
            f"{p}: checkpoint format version {data.get('format_version')}, this TSSAC reads {FORMAT_VERSION}"
        )
    return data


def learner_state(path: str | Path) -> SacState:
    """The full learner state a role checkpoint carries for transfer and fine-tuning; CheckpointError if the
    file has none (a compacted checkpoint holds the actor only). Not checked further here: loading it into a
    learner (``transfer``) raises KeyError or RuntimeError for one of another shape."""
    state: SacState | None = read_checkpoint(path).get("learner")
    if not isinstance(state, dict):
        raise CheckpointError(
            f"{path}: holds the actor only (compacted), not the learner state that transfer and --init-from need"
        )
    return state


def checkpoint_info(data: dict[str, Any], path: str | Path) -> CheckpointInfo:
    try:
        return CheckpointInfo(
            role=Role(data["role"]),
            algo=str(data["algo"]),
            observation_mode=ObservationMode(data["observation_mode"]),
            obs_dim=int(data["obs_dim"]),
            act_dim=int(data["act_dim"]),
            hidden_sizes=tuple(int(h) for h in data["hidden_sizes"]),
            scenario_digest=str(data["scenario_digest"]),
            versions=dict(data["versions"]),
            metrics=dict(data.get("metrics") or {}),
            action_repeat=check_action_repeat(int(data.get("action_repeat", 1)), str(path)),
        )
    except (KeyError, ValueError, TypeError) as exc:
        raise CheckpointError(f"{path}: checkpoint metadata is damaged ({exc})") from None


class Policy:
    """A trained role: ``policy(obs)`` / ``policy.act(obs)`` maps observations to actions in [-1, 1].

    Deterministic by default (the mean action, tanh-squashed). Works on one observation (d,) or a
    batch (n, d). ``observation_mode`` tells callers which observation to build; ``action_repeat``
    how many 0.1 s steps to hold each action (the decision interval it was trained with).
    """

    def __init__(self, info: CheckpointInfo, actor: SquashedGaussianActor, deterministic: bool = True) -> None:
        self.info = info
        self.actor = actor.eval()
        self.deterministic = deterministic
        self.observation_mode = info.observation_mode
        self.action_repeat = info.action_repeat

    @staticmethod
    def load(path: str | Path, role: Role | str | None = None, deterministic: bool = True) -> Policy:
        data = read_checkpoint(path)
        info = checkpoint_info(data, path)
        if role is not None and Role(role) is not info.role:
            raise CheckpointError(f"{path}: checkpoint is for the {info.role.value} UAV, not the {Role(role).value}")
        if info.obs_dim != info.observation_mode.size:
            raise CheckpointError(
                f"{path}: observation size {info.obs_dim} does not fit the '{info.observation_mode.value}' observation "
                f"({info.observation_mode.size})"
            )
        actor = SquashedGaussianActor(info.obs_dim, info.act_dim, info.hidden_sizes)
        try:
            actor.load_state_dict(data["actor"])
        except (KeyError, RuntimeError) as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise CheckpointError(f"{path}: actor weights do not fit ({first})") from None
        return Policy(info, actor, deterministic)

    @torch.no_grad()
    def act(self, obs: np.ndarray) -> np.ndarray:
        x = torch.as_tensor(np.asarray(obs, dtype=np.float32))
        single = x.ndim == 1
        if x.shape[-1] != self.info.obs_dim:
            raise ValueError(
                f"observation has {x.shape[-1]} values, the {self.info.role.value} policy takes {self.info.obs_dim}"
            )
        action, _ = self.actor(x.unsqueeze(0) if single else x, self.deterministic)
        out = action.numpy().astype(np.float64)
        return out[0] if single else out

    __call__ = act
    predict = act


def load_team(models: str | Path, deterministic: bool = True) -> tuple[Policy, Policy, Policy]:
    """The three role policies from a directory holding decoy.pt, detect.pt and strike.pt, after its manifest is
    checked (tssac_core.deploy.manifest: CheckpointError for a changed or missing file)."""
    d = Path(models)
    if not d.is_dir():
        raise CheckpointError(f"{d}: models directory not found")
    unchecked = check_models(d, [f"{role.value}.pt" for role in ROLES])
    decoy, detect, strike = (Policy.load(d / f"{role.value}.pt", role, deterministic) for role in ROLES)
    warn_once(unchecked)
    return decoy, detect, strike
