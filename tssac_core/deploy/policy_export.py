"""A :class:`~tssac_core.deploy.policy_spec.PolicySpec` written as an ONNX actor, and a team directory that ``fly`` and
the companion fly (``fly --models DIR``).

:func:`write_onnx_actor` writes ``DIR/<role>.onnx`` in :mod:`tssac_core.deploy.onnx_actor`'s form: the spec's own ONNX
model (:func:`~tssac_core.deploy.any_policy.from_onnx`), or the graph of its MLP layers
(:func:`tssac_core.deploy.mlp_graph.mlp_model`: Stable-Baselines3 MLP policies, torch ``nn.Sequential`` actors), with
``role``, ``observation_mode`` and ``action_repeat`` in its metadata and the spec's name as ``source``. The file is
then loaded back on onnxruntime and must give the spec's own actions (clipped to [-1, 1], as the world clips them) to
1e-5 on observations drawn from the env's observation space: a graph that flew another controller is refused in one
line, never written. A plain callable has no network to write: export the network behind it.

:func:`export_team` writes a whole team directory: the roles given as specs, the others from a models directory
(:func:`tssac_core.deploy.export.export_onnx`: the shipped team, ``models/tssac``), all recorded in ``SHA256SUMS``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from tssac_core.common.errors import CheckpointError
from tssac_core.common.files import replace_durably
from tssac_core.deploy.manifest import record
from tssac_core.deploy.policy_spec import ACTOR_STEP_S, PolicyError, PolicySpec, check_policy, steps_per_decision
from tssac_core.sim.observation import observation_bounds
from tssac_core.sim.scenario import ROLES, Role

AGREEMENT = 1e-5
"""How close the written graph's actions must be to the spec's (float32 arithmetic in two runtimes)."""
CHECK_OBSERVATIONS = 1000


def write_onnx_actor(spec: PolicySpec, role: Role | str, out: str | Path) -> Path:
    """``out/<role>.onnx`` (atomically; ``out`` made if missing), recorded in ``out/SHA256SUMS`` (module docstring)."""
    from tssac_core.deploy.onnx_actor import OnnxPolicy

    role = Role(role)
    check_policy(spec, role, ACTOR_STEP_S)
    repeat = steps_per_decision(spec.decision_interval_s, ACTOR_STEP_S, spec.name)
    props = {
        "role": role.value,
        "observation_mode": spec.observation_mode.value,
        "action_repeat": str(repeat),
        "source": spec.name,
    }
    data = model_bytes(spec, props)
    directory = Path(out)
    target = directory / f"{role.value}.onnx"
    actor = OnnxPolicy(data, str(target), role)  # onnxruntime loads and probes it before anything is written
    low, high = observation_bounds(spec.observation_mode)
    obs = np.random.default_rng(1).uniform(low, high, (CHECK_OBSERVATIONS, low.size)).astype(np.float32)
    want = np.asarray(spec.act(obs), dtype=np.float64)
    if spec.clip:
        want = np.clip(want, -1.0, 1.0)
    gap = float(np.max(np.abs(actor.act(obs) - want)))
    if not gap <= AGREEMENT:
        raise PolicyError(
            f"{spec.name}: its ONNX graph's actions differ from the policy's by up to {gap:.2g} (more than "
            f"{AGREEMENT:g}): export this network with torch.onnx.export and set its metadata (README)"
        )
    directory.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(target.name + ".tmp")
    tmp.write_bytes(data)
    replace_durably(tmp, target)
    record(directory, [target.name])
    return target


def model_bytes(spec: PolicySpec, props: Mapping[str, str]) -> bytes:
    """The serialised ONNX model of ``spec`` with the metadata ``props`` (its own model's entries kept)."""
    import onnx

    from tssac_core.deploy.mlp_graph import mlp_model

    if spec.onnx_model is not None:
        model = onnx.load_from_string(spec.onnx_model)
        old = {entry.key: entry.value for entry in model.metadata_props}
        onnx.helper.set_model_props(model, {**old, **props})
        data: bytes = model.SerializeToString()
        return data
    if spec.layers is None:
        raise PolicyError(
            f"{spec.name}: no network to write as ONNX (a plain callable, or a network that is not an MLP of Linear, "
            "Tanh and ReLU layers): export it with torch.onnx.export and set its metadata (README)"
        )
    return bytes(mlp_model(spec.layers, props, f"{props['role']}_policy").SerializeToString())


def export_team(
    out: str | Path, policies: Mapping[Role | str, PolicySpec], team: str | Path | None = None
) -> list[Path]:
    """A directory of ONNX actors for ``fly --models out``: the roles of ``policies`` written from their specs, the
    others exported from the models directory ``team`` (e.g. ``models/tssac``); CheckpointError if a role is left
    without a pilot, or ``out`` holds .pt or .npz files (one format per directory)."""
    from tssac_core.deploy.export import export_onnx

    directory = Path(out)
    given = {Role(role): spec for role, spec in policies.items()}
    rest = [role for role in ROLES if role not in given]
    if rest and team is None:
        raise CheckpointError(
            f"{directory}: no policy for the {rest[0].value} UAV: give one, or a models directory for the others "
            "(team=)"
        )
    other = [p.name for r in ROLES for p in (directory / f"{r.value}.pt", directory / f"{r.value}.npz") if p.is_file()]
    if other:
        raise CheckpointError(f"{directory}: holds {other[0]}: ONNX actors go to a directory of their own")
    written = [write_onnx_actor(spec, role, directory) for role, spec in given.items()]
    if rest:
        assert team is not None
        written += [path for path, _ in export_onnx(Path(team), directory, only=rest)]
    return written
