"""Turn role checkpoints into what deployment flies: ``<role>.npz`` exports, ``<role>.onnx`` exports, compacted
``<role>.pt``.

``python -m tssac_core.deploy.export DIR_OR_PT [...]`` writes the actor of every role checkpoint named
(a models directory: every ``<role>.pt`` in it) as ``<role>.npz`` beside it (the format:
:mod:`tssac_core.deploy.numpy_actor`), and records both files in the directory's ``SHA256SUMS``
(:mod:`tssac_core.deploy.manifest`; checked first: a changed file is refused, not exported). Training does this
itself; the command is for directories trained before the export existed.

``python -m tssac_core.deploy.export DIR --format onnx --out DIR2`` writes the actor each role of DIR flies
(:func:`~tssac_core.deploy.numpy_actor.pilot_file`) as ``DIR2/<role>.onnx`` (the format:
:mod:`tssac_core.deploy.onnx_actor`) and records them in ``DIR2/SHA256SUMS``: a directory that ``evaluate``, ``fly``
and the companion fly with onnxruntime. The graph is built from the numpy actor's arrays with the ``onnx`` package
(the ``onnx`` extra); torch only when a role's .npz is missing or stale and its .pt is read instead.

torch, onnx and onnxruntime are imported by the functions that need them, not by the module, so ``--help`` answers
without them.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tssac_core.common.cli import UsageError
from tssac_core.common.errors import CheckpointError
from tssac_core.common.files import replace_durably, sha256_file
from tssac_core.deploy.actor_meta import ActorMeta
from tssac_core.deploy.manifest import MANIFEST, check_models, record, warn_once
from tssac_core.deploy.numpy_actor import (
    FORMAT,
    FORMAT_VERSION,
    NumpyPolicy,
    holds_onnx,
    pilot_file,
    read_actor,
)
from tssac_core.deploy.onnx_actor import INSTALL
from tssac_core.sim.scenario import ROLES, Role

Layers = list[tuple[np.ndarray, np.ndarray]]
"""An MLP's Linear layers, (weight (out, in), bias (out,)) float32 each, as torch and ``<role>.npz`` keep them."""

OPSET = 17
"""The ONNX operator set of ``<role>.onnx``: every onnxruntime since 1.11 reads it (and every op used is in it)."""
IR_VERSION = 8
"""The ONNX IR version that goes with :data:`OPSET` (a newer IR would shut out older runtimes for nothing)."""


def checkpoint_actor(checkpoint: Path) -> tuple[ActorMeta, Layers]:
    """(meta, layers) of a role checkpoint's deterministic actor: what ``<role>.npz`` holds (imports torch)."""
    from torch import nn

    from tssac_core.deploy.policy import Policy

    policy = Policy.load(checkpoint)
    meta: ActorMeta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        **policy.info.fields(),
        "source": checkpoint.name,
        "source_sha256": sha256_file(checkpoint),
    }
    layers = [
        (m.weight.detach().numpy().astype(np.float32), m.bias.detach().numpy().astype(np.float32))
        for m in policy.actor.net
        if isinstance(m, nn.Linear)
    ]
    return meta, layers


def export_actor(checkpoint: str | Path, out: str | Path | None = None) -> Path:
    """Write the deterministic actor of a role checkpoint as ``<role>.npz`` beside it (or to ``out``), atomically."""
    src = Path(checkpoint)
    meta, layers = checkpoint_actor(src)
    # Any: np.savez's keywords include allow_pickle (a bool), which a dict of arrays passed as ** would clash with.
    arrays: dict[str, Any] = {"meta": np.array(json.dumps(meta))}
    for i, (w, b) in enumerate(layers):
        arrays[f"w{i}"] = w
        arrays[f"b{i}"] = b
    target = Path(out) if out is not None else src.with_suffix(".npz")
    tmp = target.with_name(target.name + ".tmp.npz")
    np.savez(tmp, **arrays)
    replace_durably(tmp, target)
    return target


def compact_checkpoint(path: str | Path) -> tuple[int, int]:
    """Drop the learner state (critics, targets, optimiser moments) from a role checkpoint, keeping the
    deployable actor and its metadata; rewritten atomically. Returns the file's size before and after."""
    from tssac_core.deploy.policy import checkpoint_info, read_checkpoint, torch_save_atomic

    p = Path(path)
    before = p.stat().st_size if p.is_file() else 0
    check_models(p.parent, [p.name], every_entry=False)  # never rewrite (and so re-record) a changed file
    data = read_checkpoint(p)
    checkpoint_info(data, p)  # refuse to rewrite a checkpoint whose metadata is damaged
    if data.get("learner") is not None:
        torch_save_atomic({**data, "learner": None}, p)
        npz = p.with_suffix(".npz")
        if npz.is_file():  # same actor, new file: the export records the file's digest
            export_actor(p)
        record(p.parent, [p.name] + ([npz.name] if npz.is_file() else []))
    return before, p.stat().st_size


def export_paths(targets: Sequence[str]) -> list[Path]:
    """Role checkpoints named by the command line: .pt files, and every <role>.pt in a directory."""
    found: list[Path] = []
    for t in map(Path, targets):
        if t.is_dir():
            pts = [t / f"{r.value}.pt" for r in ROLES if (t / f"{r.value}.pt").is_file()]
            if not pts:
                raise CheckpointError(f"{t}: no decoy.pt, detect.pt or strike.pt here")
            found += pts
        elif t.suffix == ".pt" and t.is_file():
            found.append(t)
        else:
            raise CheckpointError(f"{t}: not a role checkpoint (.pt) or a models directory")
    return found


def source_actor(models: Path, role: Role) -> tuple[Path, ActorMeta, Layers]:
    """(file, meta, layers) of the actor ``role`` flies from ``models`` (:func:`pilot_file`: the fresh .npz, numpy
    only; else the .pt, through torch), after the manifest is checked for that file."""
    src = pilot_file(models, role)
    warn_once(check_models(models, [src.name], every_entry=False))
    meta, layers = read_actor(src) if src.suffix == ".npz" else checkpoint_actor(src)
    return src, {**meta, "source": src.name, "source_sha256": sha256_file(src)}, layers


def onnx_metadata(meta: ActorMeta) -> dict[str, str]:
    """The ``metadata_props`` of ``<role>.onnx``: the numpy actor's metadata less what the graph states itself (format
    and sizes), each value a string (JSON for numbers and nested values)."""
    skip = {"format", "format_version", "obs_dim", "act_dim", "hidden_sizes"}
    return {k: v if isinstance(v, str) else json.dumps(v) for k, v in meta.items() if k not in skip}


def actor_model(meta: ActorMeta, layers: Layers) -> Any:
    """The ONNX model (``onnx.ModelProto``) of a numpy actor: obs (n, obs_dim) -> Gemm, Relu per hidden layer ->
    Gemm -> Slice of the mean half (the first act_dim outputs) -> Tanh -> action (n, act_dim), what
    :class:`~tssac_core.deploy.numpy_actor.NumpyPolicy` computes; checked by ``onnx.checker``."""
    from onnx import helper, numpy_helper

    obs_dim, act_dim = int(meta["obs_dim"]), int(meta["act_dim"])
    nodes, weights = [], []
    x = "obs"
    for i, (w, b) in enumerate(layers):
        weights += [numpy_helper.from_array(w, f"w{i}"), numpy_helper.from_array(b, f"b{i}")]
        nodes.append(helper.make_node("Gemm", [x, f"w{i}", f"b{i}"], [f"z{i}"], transB=1))  # x @ w.T + b
        x = f"z{i}"
        if i < len(layers) - 1:
            nodes.append(helper.make_node("Relu", [x], [f"h{i}"]))
            x = f"h{i}"
    for name, value in (("mean_start", 0), ("mean_end", act_dim), ("mean_axis", 1)):
        weights.append(numpy_helper.from_array(np.array([value], dtype=np.int64), name))
    nodes.append(helper.make_node("Slice", [x, "mean_start", "mean_end", "mean_axis"], ["mean"]))
    nodes.append(helper.make_node("Tanh", ["mean"], ["action"]))  # deterministic squashed Gaussian: a = tanh(mean)
    name = f"tssac_{meta['role']}_actor"
    doc = f"TSSAC {meta['role']} actor: observation -> action in [-1, 1] (tssac_core.deploy.onnx_actor)"
    return checked_model(nodes, weights, name, (obs_dim, act_dim), doc, onnx_metadata(meta))


def checked_model(
    nodes: list[Any], weights: list[Any], name: str, dims: tuple[int, int], doc: str, props: Mapping[str, str]
) -> Any:
    """The ONNX model (``onnx.ModelProto``) of a graph from ``obs`` (n, dims[0]) to ``action`` (n, dims[1]), at this
    project's opset and IR version, its ``metadata_props`` ``props``; checked by ``onnx.checker``."""
    import onnx
    from onnx import TensorProto, helper

    from tssac_core import __version__

    graph = helper.make_graph(
        nodes,
        name,
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["n", dims[0]])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["n", dims[1]])],
        weights,
    )
    model = helper.make_model(
        graph,
        opset_imports=[helper.make_opsetid("", OPSET)],
        ir_version=IR_VERSION,
        producer_name="tssac",
        producer_version=__version__,
        doc_string=doc,
    )
    helper.set_model_props(model, dict(props))
    onnx.checker.check_model(model, full_check=True)
    return model


def export_onnx(models: Path, out: Path, only: Sequence[Role] | None = None) -> list[tuple[Path, ActorMeta]]:
    """Write the actor every role of ``models`` flies (of the roles ``only``, if given) as ``out/<role>.onnx`` (each
    atomically) and record them in ``out/SHA256SUMS``; ``out`` is made if missing and must hold no .pt or .npz (one
    format per directory). Returns each file written with the metadata of the actor it was made from."""
    roles = [r for r in ROLES if (models / f"{r.value}.pt").is_file() or (models / f"{r.value}.npz").is_file()]
    if holds_onnx(models):
        raise CheckpointError(f"{models}: holds ONNX actors already; export the directory they came from")
    if not roles:
        raise CheckpointError(f"{models}: no <role>.pt or <role>.npz here")
    if only is not None:
        missing = [r.value for r in only if r not in roles]
        if missing:
            raise CheckpointError(f"{models}: no {missing[0]}.pt or {missing[0]}.npz here")
        roles = [r for r in roles if r in only]
    _onnx_package()
    out.mkdir(parents=True, exist_ok=True)
    other = [p.name for r in ROLES for p in (out / f"{r.value}.pt", out / f"{r.value}.npz") if p.is_file()]
    if other:
        raise CheckpointError(f"{out}: holds {other[0]}: ONNX actors go to a directory of their own")
    written = []
    for role in roles:
        _, meta, layers = source_actor(models, role)
        target = out / f"{role.value}.onnx"
        tmp = target.with_name(target.name + ".tmp")
        tmp.write_bytes(actor_model(meta, layers).SerializeToString())
        replace_durably(tmp, target)
        written.append((target, meta))
    record(out, [path.name for path, _ in written])
    return written


def _onnx_package() -> None:
    """CheckpointError with the install line unless the ``onnx`` package (what builds the graphs) imports."""
    try:
        import onnx  # noqa: F401
    except ImportError:
        raise CheckpointError(f"export --format onnx needs the onnx package ({INSTALL})") from None


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m tssac_core.deploy.export",
        description="Export trained role checkpoints' actors as <role>.npz, which the companion flies without torch, "
        "or a models directory's actors as <role>.onnx in a directory of their own (--format onnx --out DIR2).",
    )
    p.add_argument(
        "targets", nargs="+", metavar="DIR_OR_PT", help="a models directory (every <role>.pt in it) or .pt files"
    )
    p.add_argument(
        "--format",
        choices=("npz", "onnx"),
        default="npz",
        help="npz: <role>.npz beside each checkpoint (default); onnx: the actor each role of one models directory "
        "flies, as <role>.onnx in --out (onnxruntime flies them)",
    )
    p.add_argument(
        "--out", type=Path, metavar="DIR2", help="with --format onnx: the directory to write (made if missing)"
    )
    args = p.parse_args(argv)
    if args.format == "onnx":
        return main_onnx(args.targets, args.out)
    if args.out is not None:
        raise UsageError("--out is for --format onnx: a <role>.npz is written beside its checkpoint")
    pts = export_paths(args.targets)
    # The checkpoints it reads, before anything is written: a changed one is refused, not exported and recorded.
    unchecked = [check_models(pt.parent, [pt.name], every_entry=False) for pt in pts]
    for pt, note in zip(pts, unchecked):
        out = export_actor(pt)
        warn_once(note)
        record(pt.parent, [pt.name, out.name])
        policy = NumpyPolicy.load(out)
        print(f"wrote {out} ({policy.role.value}, actor {_shape(policy.meta)}, {out.stat().st_size / 1024:.0f} KB)")
    return 0


def main_onnx(targets: Sequence[str], out: Path | None) -> int:
    """``--format onnx``: one models directory's actors to ``out``, each file loaded back on onnxruntime."""
    from tssac_core.deploy.onnx_actor import OnnxPolicy

    if out is None:
        raise UsageError("--format onnx writes a directory of its own: give it with --out DIR2")
    if len(targets) != 1:
        raise UsageError("--format onnx exports one models directory (DIR --format onnx --out DIR2)")
    models = Path(targets[0])
    if not models.is_dir():
        raise CheckpointError(f"{models}: models directory not found")
    for path, meta in export_onnx(models, out):
        OnnxPolicy.load(path, meta["role"])  # onnxruntime reads it back and runs it
        print(
            f"wrote {path} ({meta['role']}, actor {_shape(meta)}, from {meta['source']}, "
            f"{path.stat().st_size / 1024:.0f} KB)"
        )
    print(f"wrote {out / MANIFEST}")
    return 0


def _shape(meta: ActorMeta) -> str:
    """The actor's layer sizes, ``24->128->128->4``."""
    return "->".join(str(n) for n in [meta["obs_dim"], *meta["hidden_sizes"], 2 * int(meta["act_dim"])])


if __name__ == "__main__":
    from tssac_core.common.cli import run

    raise SystemExit(run(main))
