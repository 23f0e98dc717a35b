"""OmniSafe's deterministic actor as numpy arrays (``actor.npz``), flown in the project's environment.

OmniSafe saves ``torch_save/epoch-<n>.pt`` = {"pi": the actor's state dict, "obs_normalizer": its observation
normalizer's, when ``obs_normalize``}; its Evaluator rebuilds the actor with ActorBuilder and wraps the env in
ObsNormalize (clip 5) and ActionScale. ``omnisafe_side`` reads that file in OmniSafe's environment and writes:

    meta        JSON: format, algo, actor_type (gaussian_learning: on-policy, mean = MLP(obs), unbounded;
                gaussian_sac: MLP(obs) = [mean, log_std], action tanh(mean)), activation, obs_clip, the source file
    obs_mean, obs_std   the normalizer's, frozen (absent without obs_normalize)
    w0, b0, w1, b1, ...  the Linear layers, weights (out, in) as in torch

:class:`OmniSafeActor` computes what ``actor.predict(obs, deterministic=True)`` does behind OmniSafe's wrappers,
then clips to [-1, 1] as the world does: normalise (frozen; OmniSafe's Evaluator would keep updating it), the MLP
with the activation after every layer but the last, the first ``act_dim`` outputs, tanh for gaussian_sac.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from tssac_core.sim.observation import ObservationMode

FORMAT = "omnisafe-actor-npz"
ACTOR_TYPES = ("gaussian_learning", "gaussian_sac")
ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {"tanh": np.tanh, "relu": lambda x: np.maximum(x, 0.0)}


class ActorFileError(ValueError):
    """An actor.npz that is not one (the command prints it as one line)."""


def write_actor(
    path: Path,
    meta: dict[str, Any],
    layers: list[tuple[np.ndarray, np.ndarray]],
    obs_mean: np.ndarray | None = None,
    obs_std: np.ndarray | None = None,
) -> None:
    """Write an actor.npz (module docstring); ``meta`` needs algo, actor_type, activation, act_dim."""
    arrays: dict[str, Any] = {}
    for i, (w, b) in enumerate(layers):
        arrays[f"w{i}"], arrays[f"b{i}"] = np.asarray(w, np.float32), np.asarray(b, np.float32)
    if obs_mean is not None and obs_std is not None:
        arrays["obs_mean"], arrays["obs_std"] = np.asarray(obs_mean, np.float64), np.asarray(obs_std, np.float64)
    full = {"format": FORMAT, "layers": len(layers), **meta}
    np.savez(path, meta=np.array(json.dumps(full)), **arrays)


class OmniSafeActor:
    """A pilot (a PilotSpec of tssac_core.sim.pilots): route observations (N, d) -> actions (N, 2), one decision per
    ``action_repeat`` world steps."""

    observation_mode = ObservationMode.ROUTE

    def __init__(
        self,
        meta: dict[str, Any],
        layers: list[tuple[np.ndarray, np.ndarray]],
        obs_mean: np.ndarray | None,
        obs_std: np.ndarray | None,
    ) -> None:
        if meta.get("format") != FORMAT:
            raise ActorFileError(f"not an {FORMAT} file (format {meta.get('format')!r})")
        if meta.get("actor_type") not in ACTOR_TYPES:
            raise ActorFileError(f"actor_type must be one of {', '.join(ACTOR_TYPES)}, got {meta.get('actor_type')!r}")
        if meta.get("activation") not in ACTIVATIONS:
            raise ActorFileError(f"activation must be one of {', '.join(ACTIVATIONS)}, got {meta.get('activation')!r}")
        if not layers:
            raise ActorFileError("no layers")
        self.meta = meta
        self.act_dim = int(meta["act_dim"])
        self.action_repeat = int(meta.get("action_repeat", 10))
        self.obs_clip = float(meta.get("obs_clip", 5.0))
        self._act = ACTIVATIONS[meta["activation"]]
        self._squash = meta["actor_type"] == "gaussian_sac"
        self._layers = [
            (np.ascontiguousarray(np.asarray(w, np.float64).T), np.asarray(b, np.float64)) for w, b in layers
        ]
        self._mean, self._std = obs_mean, obs_std
        if self._layers[0][0].shape[0] != self.observation_mode.size:
            raise ActorFileError(
                f"the actor takes {self._layers[0][0].shape[0]} inputs, the route observation has "
                f"{self.observation_mode.size}"
            )

    @staticmethod
    def load(path: str | Path) -> OmniSafeActor:
        p = Path(path)
        try:
            with np.load(p, allow_pickle=False) as data:
                meta = json.loads(str(data["meta"]))
                layers = [(data[f"w{i}"], data[f"b{i}"]) for i in range(int(meta["layers"]))]
                mean = data["obs_mean"] if "obs_mean" in data else None
                std = data["obs_std"] if "obs_std" in data else None
        except (OSError, KeyError, ValueError) as exc:
            raise ActorFileError(f"{p}: cannot read an actor: {exc}") from None
        return OmniSafeActor(meta, layers, mean, std)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        x = np.asarray(obs, np.float64)
        if self._mean is not None and self._std is not None:
            x = np.clip((x - self._mean) / self._std, -self.obs_clip, self.obs_clip)
        for i, (w, b) in enumerate(self._layers):
            x = x @ w + b
            if i < len(self._layers) - 1:
                x = self._act(x)
        mean = x[..., : self.act_dim]
        action = np.tanh(mean) if self._squash else mean
        return np.clip(action, -1.0, 1.0)

    act = __call__
    predict = __call__
