"""A trained role's actor as a numpy file (``<role>.npz``), flown without torch.

The companion computer runs one small MLP per control decision. Importing torch to do that costs about
2 s of CPU per process start and a few hundred MB of memory, on hardware where both are scarce, and
``fly`` starts three companions per mission. So training writes, beside every shipped ``<role>.pt``,
the deterministic actor as plain arrays:

    <role>.npz:  meta  JSON: format, the checkpoint's metadata (role, algo, observation mode and size,
                       action size, hidden sizes, action_repeat, scenario digest, versions, metrics)
                       and the SHA-256 of the .pt it came from
                 w0, b0, w1, b1, ...  the Linear layers, float32, weights (out, in) as in torch

and :class:`NumpyPolicy` computes what ``Policy(deterministic=True)`` does: the MLP with ReLU after every
layer but the last, then a = tanh(mean) (the first ``act_dim`` outputs; the log-std half is unused).

For a models directory made by an older version (or trained elsewhere), export by hand:

    python -m tssac_core.deploy.export models/tssac [more dirs or .pt files]

:func:`pilot_file` picks what a role flies from a models directory: the .npz when it was exported from
the .pt beside it (or stands alone), else the .pt, so a retrained .pt is never shadowed by a stale export; in a
directory of ONNX actors (``export --format onnx``, :mod:`tssac_core.deploy.onnx_actor`), the ``<role>.onnx``.
"""

from __future__ import annotations

import json
import logging
import zipfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Protocol

import numpy as np

from tssac_core.common.errors import CheckpointError, check_action_repeat
from tssac_core.common.files import sha256_file
from tssac_core.deploy.actor_meta import ActorMeta
from tssac_core.deploy.manifest import check_model_file, warn_once
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.scenario import ROLES, Role

FORMAT = "tssac-actor-npz"
FORMAT_VERSION = 1


logger = logging.getLogger(__name__)


class Actor(Protocol):
    """What a pilot needs of a trained policy (``Policy``, ``NumpyPolicy`` and ``OnnxPolicy`` each are one)."""

    observation_mode: ObservationMode
    action_repeat: int

    def act(self, obs: np.ndarray) -> np.ndarray: ...

    def predict(self, obs: np.ndarray) -> np.ndarray: ...

    def __call__(self, obs: np.ndarray) -> np.ndarray: ...


class NumpyPolicy:
    """The deterministic actor of an exported ``<role>.npz``: ``act(obs) -> action`` in [-1, 1], float64."""

    def __init__(self, meta: ActorMeta, layers: list[tuple[np.ndarray, np.ndarray]]) -> None:
        self.meta = meta
        self.role = Role(meta["role"])
        self.observation_mode = ObservationMode(meta["observation_mode"])
        self.obs_dim = int(meta["obs_dim"])
        self.act_dim = int(meta["act_dim"])
        self.action_repeat = int(meta["action_repeat"])
        # Stored as torch keeps them, (out, in); transposed once here so that act() is x @ w + b.
        self._layers = [(np.ascontiguousarray(w.T), b) for w, b in layers]

    @staticmethod
    def load(path: str | Path, role: Role | str | None = None) -> NumpyPolicy:
        p = Path(path)
        meta, layers = read_actor(p)
        if role is not None and Role(role) is not Role(meta["role"]):
            raise CheckpointError(f"{p}: exported actor is for the {meta['role']} UAV, not the {Role(role).value}")
        return NumpyPolicy(meta, layers)

    def act(self, obs: np.ndarray) -> np.ndarray:
        x = np.asarray(obs, dtype=np.float32)
        single = x.ndim == 1
        if x.shape[-1] != self.obs_dim:
            raise ValueError(f"observation has {x.shape[-1]} values, the {self.role.value} policy takes {self.obs_dim}")
        h = x[None] if single else x
        for w, b in self._layers[:-1]:
            h = h @ w
            h += b
            np.maximum(h, 0.0, out=h)  # ReLU
        w, b = self._layers[-1]
        mean = (h @ w + b)[:, : self.act_dim]
        out = np.tanh(mean).astype(np.float64)  # deterministic squashed Gaussian: a = tanh(mean)
        return out[0] if single else out

    __call__ = act
    predict = act
    """The action for ``obs`` (one (d,) or a batch (n, d)): what a gymnasium user calls."""


def read_actor(p: Path) -> tuple[ActorMeta, list[tuple[np.ndarray, np.ndarray]]]:
    """(meta, layers) of an exported actor; CheckpointError (one line) for anything wrong with the file."""
    if not p.is_file():
        raise CheckpointError(f"{p}: exported actor not found")
    try:
        with np.load(p, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise CheckpointError(f"{p}: not a readable .npz file ({type(exc).__name__})") from None
    try:
        meta: ActorMeta = json.loads(str(arrays.pop("meta")))
    except (KeyError, ValueError):
        raise CheckpointError(f"{p}: not an exported TSSAC actor (no readable meta)") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise CheckpointError(f"{p}: not an exported TSSAC actor")
    if meta.get("format_version") != FORMAT_VERSION:
        raise CheckpointError(
            f"{p}: exported actor format version {meta.get('format_version')}, this TSSAC reads {FORMAT_VERSION}"
        )
    try:
        mode = ObservationMode(meta["observation_mode"])
        Role(meta["role"])
        sizes = [int(meta["obs_dim"]), *(int(h) for h in meta["hidden_sizes"]), 2 * int(meta["act_dim"])]
        check_action_repeat(int(meta["action_repeat"]), str(p))
    except (KeyError, ValueError, TypeError) as exc:
        raise CheckpointError(f"{p}: exported actor metadata is damaged ({exc})") from None
    if sizes[0] != mode.size:
        raise CheckpointError(
            f"{p}: observation size {sizes[0]} does not fit the '{mode.value}' observation ({mode.size})"
        )
    layers = []
    for i, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:])):
        w, b = arrays.get(f"w{i}"), arrays.get(f"b{i}")
        if w is None or b is None or w.shape != (fan_out, fan_in) or b.shape != (fan_out,):
            raise CheckpointError(f"{p}: layer {i} is missing or not {fan_out}x{fan_in}")
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
            raise CheckpointError(f"{p}: layer {i} holds non-finite weights")
        layers.append((w.astype(np.float32), b.astype(np.float32)))
    return meta, layers


def holds_onnx(models: str | Path) -> bool:
    """Whether ``models`` is a directory of ONNX actors: it holds a ``<role>.onnx``."""
    return any((Path(models) / f"{role.value}.onnx").is_file() for role in ROLES)


def pilot_file(models: str | Path, role: Role) -> Path:
    """The file ``role`` flies from a models directory: ``<role>.npz`` if it was exported from the
    ``<role>.pt`` beside it (or there is no .pt), otherwise ``<role>.pt`` (with a warning if a stale
    export is being passed over); in a directory of ONNX actors, ``<role>.onnx`` (CheckpointError if
    that directory holds the role's .pt or .npz too: which of them was meant to fly?)."""
    d = Path(models)
    pt, npz = d / f"{role.value}.pt", d / f"{role.value}.npz"
    if holds_onnx(d):
        beside = [p.name for p in (pt, npz) if p.is_file()]
        if beside:
            raise CheckpointError(
                f"{d}: ONNX actors beside {beside[0]}: one format per models directory (export --format onnx --out "
                f"writes a directory of its own)"
            )
        return d / f"{role.value}.onnx"
    if not npz.is_file():
        return pt
    if not pt.is_file():
        return npz
    try:
        source = read_actor(npz)[0].get("source_sha256")
    except CheckpointError as exc:
        logger.warning("%s; flying %s instead", exc, pt)
        return pt
    if source == sha256_file(pt):
        return npz
    logger.warning(
        "%s was exported from another %s: flying the .pt (refresh with python -m tssac_core.deploy.export %s)",
        npz,
        pt.name,
        d,
    )
    return pt


def load_actor(path: str | Path, role: Role | str | None = None) -> Actor:
    """A deterministic role policy from ``<role>.npz`` (numpy only), ``<role>.onnx`` (imports onnxruntime) or
    ``<role>.pt`` (imports torch), after the manifest of its directory is checked (tssac_core.deploy.manifest:
    CheckpointError for a changed file)."""
    unchecked = check_model_file(Path(path))
    suffix = Path(path).suffix
    if suffix == ".npz":
        actor: Actor = NumpyPolicy.load(path, role)
    elif suffix == ".onnx":
        from tssac_core.deploy.onnx_actor import OnnxPolicy

        actor = OnnxPolicy.load(path, role)
    else:
        from tssac_core.deploy.policy import Policy

        actor = Policy.load(path, role)
    warn_once(unchecked)
    return actor


def load_policy(path: str | Path, role: Role | str | None = None) -> Actor:
    """A shipped or trained actor to fly in ``gym.make("tssac/<Role>-v0")``: ``load_policy(path).predict(obs)``
    is the action for an observation. ``path``: a ``<role>.npz`` (numpy only), ``<role>.onnx`` (onnxruntime) or
    ``<role>.pt`` (imports torch), or a models directory with ``role`` (the file :func:`pilot_file` picks). Its
    ``observation_mode`` and ``action_repeat`` say which env settings it was trained with (the env's defaults are the
    shipped team's)."""
    p = Path(path)
    if p.is_dir():
        if role is None:
            raise CheckpointError(f"{p}: a models directory: say which role's actor to load")
        p = pilot_file(p, Role(role))
    return load_actor(p, role)


def team_pilots(models: str | Path, roles: Sequence[Role | str]) -> Mapping[str, Actor]:
    """Teammates for the gymnasium env or the OmniSafe adapter: ``roles`` flown by their actors in ``models``
    (e.g. ``team_pilots("models/tssac", ["decoy"])`` beside a learning detect UAV, as training flies it)."""
    return {Role(r).value: load_policy(models, r) for r in roles}
