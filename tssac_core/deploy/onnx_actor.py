"""A role's actor as an ONNX file (``<role>.onnx``), flown with onnxruntime: a policy from any framework.

The file is all a pilot needs. Its graph maps the role's observation to the action:

    input   float32 (n, obs_dim)   the observation, obs_dim = the observation mode's size (24 for ``route``)
    output  float32 (n, 2)         the action [omega, u] in [-1, 1] (squashed: tanh applied in the graph)

and what the graph cannot say is in the model's ``metadata_props`` (string -> string; the one place it is kept, so
that ``--model X.onnx`` alone is complete and ``SHA256SUMS`` covers it with the graph):

    role               decoy | detect | strike
    observation_mode   paper | extended | route
    action_repeat      0.1 s world steps between decisions (10: one decision per simulated second)

Required; any other entries are provenance, carried and not read (the export adds ``algo``, ``scenario_digest``,
``versions``, ``metrics``, ``source`` and ``source_sha256``: the file it was made from and that file's SHA-256).

``python -m tssac_core.deploy.export DIR --format onnx --out DIR2`` writes a team's actors so
(:func:`tssac_core.deploy.export.export_onnx`); a policy trained elsewhere flies once its graph has that form and its
file those three entries. :class:`OnnxPolicy` is :class:`~tssac_core.deploy.numpy_actor.NumpyPolicy`'s face on
onnxruntime. onnxruntime (the ``onnx`` extra) is imported when the first ONNX actor loads, never by importing this
module: commands that fly no ONNX file never import it.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from tssac_core.common.errors import CheckpointError
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.scenario import Role

ACTION_SIZE = 2
"""The action [omega, u] (the env's ``Box(-1, 1, (2,))``)."""
REQUIRED = ("role", "observation_mode", "action_repeat")
"""The ``metadata_props`` entries a pilot reads."""
INSTALL = "pip install -e '.[onnx]'"

_ORT_ERRORS = (
    "EngineError",
    "Fail",
    "InvalidArgument",
    "InvalidGraph",
    "InvalidProtobuf",
    "NoModel",
    "NoSuchFile",
    "NotImplemented",
    "RuntimeException",
)
"""onnxruntime's exception classes (``onnxruntime.capi.onnxruntime_pybind11_state``; each derives from Exception)."""


def _onnxruntime(path: Path) -> Any:
    """The onnxruntime module, imported now; CheckpointError naming ``path`` and the install line if it is missing."""
    try:
        import onnxruntime
    except ImportError:
        raise CheckpointError(f"{path}: flying an ONNX actor needs onnxruntime ({INSTALL})") from None
    return onnxruntime


def _ort_errors() -> tuple[type[Exception], ...]:
    from onnxruntime.capi import onnxruntime_pybind11_state as state

    return tuple(getattr(state, name) for name in _ORT_ERRORS if hasattr(state, name))


def session_options(ort: Any) -> Any:
    """One thread, run in sequence, warnings off: a companion computer's budget. One decision is a small MLP (24 ->
    128 -> 128 -> 4: about 20k multiply-adds, microseconds); a thread pool would add its hand-offs to every call and,
    as onnxruntime's pool spins while it waits, take cores from the other companions and the vehicle's own software
    (``fly`` runs three companions and the SITL on two cores). The batched evaluation stays on one core too, as a
    Ray worker should."""
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.log_severity_level = 3  # errors only: no foreign warnings on a command's console
    return options


class OnnxPolicy:
    """The actor of a ``<role>.onnx``: ``act(obs) -> action`` in [-1, 1], float64, on onnxruntime (one thread).

    ``obs``: one observation (obs_dim,) or a batch (n, obs_dim); the action (2,) or (n, 2). A graph made for one
    observation at a time (its input (1, obs_dim), as exporters write without a dynamic batch axis) is called row by
    row for a batch. Pickles as the file's bytes (a Ray worker builds its own session)."""

    def __init__(self, model: bytes, name: str, role: Role | str | None = None) -> None:
        ort = _onnxruntime(Path(name))
        try:
            session = ort.InferenceSession(model, sess_options=session_options(ort), providers=["CPUExecutionProvider"])
        except _ort_errors() as exc:
            raise CheckpointError(f"{name}: not a loadable ONNX model ({_first_line(exc)})") from None
        self.name = name
        self.meta: dict[str, str] = dict(session.get_modelmeta().custom_metadata_map)
        self.role, self.observation_mode, self.action_repeat = read_metadata(self.meta, name)
        if role is not None and Role(role) is not self.role:
            raise CheckpointError(f"{name}: ONNX actor is for the {self.role.value} UAV, not the {Role(role).value}")
        self.obs_dim, self.act_dim = self.observation_mode.size, ACTION_SIZE
        self._model = model
        self._session = session
        self._input, self._output = _check_io(session, self.observation_mode, name)
        self._row_by_row = session.get_inputs()[0].shape[0] == 1
        _probe(self._run, self.obs_dim, 1 if self._row_by_row else 2, name)
        self._one = OneObservation(ort, session, self._input, self._output, self.obs_dim)

    @staticmethod
    def load(path: str | Path, role: Role | str | None = None) -> OnnxPolicy:
        """The actor in ``path``; CheckpointError (one line) for a missing, corrupt or foreign file, or another role."""
        p = Path(path)
        if not p.is_file():
            raise CheckpointError(f"{p}: ONNX actor not found")
        return OnnxPolicy(p.read_bytes(), str(p), role)

    def act(self, obs: np.ndarray) -> np.ndarray:
        x = np.asarray(obs, dtype=np.float32)
        if x.shape[-1] != self.obs_dim:
            raise ValueError(f"observation has {x.shape[-1]} values, the {self.role.value} policy takes {self.obs_dim}")
        if x.ndim == 1:
            return self._one(x)
        if self._row_by_row:
            return np.array([self._one(row) for row in x]).reshape(len(x), self.act_dim)
        return np.asarray(self._run(x), dtype=np.float64)

    __call__ = act
    predict = act
    """The action for ``obs`` (one (d,) or a batch (n, d)): what a gymnasium user calls."""

    def _run(self, x: np.ndarray) -> np.ndarray:
        """The graph's output for a batch ``x`` (n, obs_dim) float32."""
        return self._session.run([self._output], {self._input: x})[0]

    def __reduce__(self) -> tuple[Any, ...]:
        return (OnnxPolicy, (self._model, self.name, self.role))


class OneObservation:
    """The companion's call, one observation (obs_dim,) -> action (2,) float64, with the graph's input and output bound
    once to buffers of their own (onnxruntime's I/O binding, zero-copy on the CPU): no feed dict and no output arrays
    built per call, about a third of the call's time (benchmarks/bench_onnx.py)."""

    def __init__(self, ort: Any, session: Any, input_name: str, output_name: str, obs_dim: int) -> None:
        self.obs = np.zeros((1, obs_dim), dtype=np.float32)
        self.action = np.zeros((1, ACTION_SIZE), dtype=np.float32)
        self._session = session
        self._binding = session.io_binding()
        self._binding.bind_ortvalue_input(input_name, ort.OrtValue.ortvalue_from_numpy(self.obs))
        self._binding.bind_ortvalue_output(output_name, ort.OrtValue.ortvalue_from_numpy(self.action))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        self.obs[0] = x
        self._session.run_with_iobinding(self._binding)
        return self.action[0].astype(np.float64)


def read_metadata(meta: dict[str, str], name: str) -> tuple[Role, ObservationMode, int]:
    """(role, observation mode, action_repeat) from a model's ``metadata_props``; CheckpointError naming the first
    missing or unreadable entry."""
    missing = [key for key in REQUIRED if key not in meta]
    if missing:
        raise CheckpointError(
            f"{name}: no '{missing[0]}' in the model's metadata_props (a TSSAC actor states {', '.join(REQUIRED)})"
        )
    try:
        role = Role(meta["role"])
    except ValueError:
        raise CheckpointError(f"{name}: metadata role {meta['role']!r} is not decoy, detect or strike") from None
    try:
        mode = ObservationMode(meta["observation_mode"])
    except ValueError:
        modes = ", ".join(m.value for m in ObservationMode)
        raise CheckpointError(
            f"{name}: metadata observation_mode {meta['observation_mode']!r} is not {modes}"
        ) from None
    try:
        repeat = int(meta["action_repeat"])
    except ValueError:
        repeat = 0
    if repeat < 1:
        raise CheckpointError(f"{name}: metadata action_repeat {meta['action_repeat']!r} is not a positive integer")
    return role, mode, repeat


def _check_io(session: Any, mode: ObservationMode, name: str) -> tuple[str, str]:
    """The graph's input and output names, after checking it has one of each, both float32, the input as wide as the
    metadata's observation (a symbolic width is taken on trust here: :func:`_probe` runs it)."""
    inputs, outputs = session.get_inputs(), session.get_outputs()
    if len(inputs) != 1 or len(outputs) != 1:
        raise CheckpointError(
            f"{name}: the graph has {len(inputs)} inputs and {len(outputs)} outputs; an actor has one of each "
            f"(observation -> action)"
        )
    for what, arg in (("input", inputs[0]), ("output", outputs[0])):
        if arg.type != "tensor(float)":
            raise CheckpointError(f"{name}: the graph's {what} is {arg.type}, not tensor(float) (float32)")
    shape = inputs[0].shape
    if len(shape) != 2:
        raise CheckpointError(f"{name}: the graph's input has {len(shape)} axes, not 2 (batch, observation)")
    if isinstance(shape[1], int) and shape[1] != mode.size:
        raise CheckpointError(
            f"{name}: the graph takes {shape[1]} observation values, the '{mode.value}' observation has {mode.size}"
        )
    return inputs[0].name, outputs[0].name


def _probe(run: Callable[[np.ndarray], np.ndarray], obs_dim: int, n: int, name: str) -> None:
    """One call of ``run`` on a batch of ``n`` zero observations: the action must come back (n, 2), finite, in
    [-1, 1]."""
    try:
        action = np.asarray(run(np.zeros((n, obs_dim), dtype=np.float32)))
    except _ort_errors() as exc:
        raise CheckpointError(
            f"{name}: the graph does not run on a ({n}, {obs_dim}) batch of observations ({_first_line(exc)})"
        ) from None
    if action.shape != (n, ACTION_SIZE):
        raise CheckpointError(
            f"{name}: the graph's output is {action.shape[1:]} per observation, not the action's ({ACTION_SIZE},)"
        )
    if not (np.all(np.isfinite(action)) and np.all(np.abs(action) <= 1.0)):
        raise CheckpointError(f"{name}: the graph's action is not finite within [-1, 1] (is tanh applied?)")


def _first_line(exc: Exception) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__
