"""Turn role checkpoints into what deployment flies: ``<role>.npz`` exports, compacted ``<role>.pt``.

``python -m tssac_core.deploy.export DIR_OR_PT [...]`` writes the actor of every role checkpoint named
(a models directory: every ``<role>.pt`` in it) as ``<role>.npz`` beside it (the format:
:mod:`tssac_core.deploy.numpy_actor`), and records both files in the directory's ``SHA256SUMS``
(:mod:`tssac_core.deploy.manifest`; checked first: a changed file is refused, not exported). Training does this
itself; the command is for directories trained before the export existed. torch is imported by the functions that
read checkpoints, not by the module, so ``--help`` answers without it.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tssac_core.common.errors import CheckpointError
from tssac_core.common.files import replace_durably
from tssac_core.deploy.manifest import check_models, record, warn_once
from tssac_core.deploy.numpy_actor import FORMAT, FORMAT_VERSION, NumpyPolicy, sha256_file
from tssac_core.sim.scenario import ROLES


def export_actor(checkpoint: str | Path, out: str | Path | None = None) -> Path:
    """Write the deterministic actor of a role checkpoint as ``<role>.npz`` beside it (or to ``out``), atomically."""
    from torch import nn

    from tssac_core.deploy.policy import Policy

    src = Path(checkpoint)
    policy = Policy.load(src)
    linears = [m for m in policy.actor.net if isinstance(m, nn.Linear)]
    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        **policy.info.fields(),
        "source": src.name,
        "source_sha256": sha256_file(src),
    }
    arrays: dict[str, Any] = {"meta": np.array(json.dumps(meta))}
    for i, layer in enumerate(linears):
        arrays[f"w{i}"] = layer.weight.detach().numpy().astype(np.float32)
        arrays[f"b{i}"] = layer.bias.detach().numpy().astype(np.float32)
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


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m tssac_core.deploy.export",
        description="Export trained role checkpoints' actors as <role>.npz, which the companion flies without torch.",
    )
    p.add_argument(
        "targets", nargs="+", metavar="DIR_OR_PT", help="a models directory (every <role>.pt in it) or .pt files"
    )
    args = p.parse_args(argv)
    pts = export_paths(args.targets)
    # The checkpoints it reads, before anything is written: a changed one is refused, not exported and recorded.
    unchecked = [check_models(pt.parent, [pt.name], every_entry=False) for pt in pts]
    for pt, note in zip(pts, unchecked):
        out = export_actor(pt)
        warn_once(note)
        record(pt.parent, [pt.name, out.name])
        policy = NumpyPolicy.load(out)
        shape = "->".join(str(n) for n in [policy.obs_dim, *policy.meta["hidden_sizes"], 2 * policy.act_dim])
        print(f"wrote {out} ({policy.role.value}, actor {shape}, {out.stat().st_size / 1024:.0f} KB)")
    return 0


if __name__ == "__main__":
    from tssac_core.common.cli import run

    raise SystemExit(run(main))
