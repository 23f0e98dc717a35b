"""OmniSafe trains one TSSAC role for a few epochs through the adapter (tssac_core.train.omnisafe_env): the
README's snippet, run in OmniSafe's own environment (it pins gymnasium 0.28.1), not in the project's.

    PYTHONPATH=. $(python benchmarks/omnisafe_env.py) benchmarks/omnisafe_train.py [--algo PPOLag] [--role Detect] \
        [--epochs 3]

Prints OmniSafe's per-epoch EpRet and EpCost and writes them as JSON (``--json``, benchmarks/output.py). The detect role
is trained with the shipped decoy flying (``teammates`` = models/tssac, ``teammate_roles`` = ["decoy"]), as the
curriculum trains it; ``--teammates guidance`` flies the guidance controller instead.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # benchmarks.*, and tssac_core in OmniSafe's environment (PYTHONPATH=. also does)

from benchmarks.output import add_json_option, write_figures  # noqa: E402
from tssac_core.common.cli import command_description  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    p.add_argument("--algo", default="PPOLag", help="an OmniSafe algorithm (PPOLag, CPO, SACLag, ...)")
    p.add_argument("--role", default="Detect", choices=["Decoy", "Detect", "Strike"])
    p.add_argument("--epochs", type=int, default=3)
    p.add_argument("--steps-per-epoch", type=int, default=2000, help="decisions of 1 s per epoch")
    p.add_argument("--teammates", default=str(ROOT / "models" / "tssac"))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=ROOT / "runs" / "omnisafe")
    add_json_option(p, "omnisafe_train")
    args = p.parse_args()

    import omnisafe  # OmniSafe's own environment only
    import omnisafe.algorithms.algo_wrapper as wrapper

    import tssac_core.train.omnisafe_env  # noqa: F401  (registers TssacDecoy-v0, TssacDetect-v0, TssacStrike-v0)
    from benchmarks.crosscheck.omnisafe_side import default_cfgs_with_env_section

    # OmniSafe 0.5.0's off-policy yamls (SACLag, ...) have no env_cfgs section, so it refuses ours without this.
    wrapper.get_default_kwargs_yaml = default_cfgs_with_env_section(wrapper.get_default_kwargs_yaml)

    env_cfgs: dict[str, object] = {"scenario": str(ROOT / "scenarios" / "random.yaml"), "teammates": args.teammates}
    if args.teammates not in ("guidance", "none") and args.role != "Decoy":
        env_cfgs["teammate_roles"] = ["decoy"] if args.role == "Detect" else ["decoy", "detect"]
    custom_cfgs = {
        "seed": args.seed,
        "train_cfgs": {"total_steps": args.epochs * args.steps_per_epoch, "vector_env_nums": 1, "torch_threads": 1},
        "algo_cfgs": {"steps_per_epoch": args.steps_per_epoch},
        "logger_cfgs": {
            "log_dir": str(args.out),
            "use_wandb": False,
            "use_tensorboard": False,
            "save_model_freq": 1000,
        },
        "env_cfgs": env_cfgs,
    }
    start = time.perf_counter()
    agent = omnisafe.Agent(args.algo, f"Tssac{args.role}-v0", custom_cfgs=custom_cfgs)
    ep_ret, ep_cost, ep_len = agent.learn()
    wall = time.perf_counter() - start
    progress = sorted(args.out.rglob("progress.csv"), key=os.path.getmtime)[-1]
    with progress.open() as fh:
        rows = list(csv.DictReader(fh))
    epochs = [
        {k: float(r[k]) for k in ("Train/Epoch", "Metrics/EpRet", "Metrics/EpCost", "Metrics/EpLen") if k in r}
        for r in rows
    ]
    for e in epochs:
        print(
            f"epoch {int(e['Train/Epoch'])}: EpRet {e['Metrics/EpRet']:.1f}  EpCost {e['Metrics/EpCost']:.1f}  "
            f"EpLen {e['Metrics/EpLen']:.0f}"
        )
    result = {
        "algo": args.algo,
        "env_id": f"Tssac{args.role}-v0",
        "env_cfgs": env_cfgs,
        "epochs": epochs,
        "final": {"EpRet": float(ep_ret), "EpCost": float(ep_cost), "EpLen": float(ep_len)},
        "wall_s": round(wall, 1),
        "progress_csv": str(progress.relative_to(ROOT)) if progress.is_relative_to(ROOT) else str(progress),
    }
    print(f"trained {args.algo} on Tssac{args.role}-v0 for {args.epochs} epochs in {wall:.0f} s")
    write_figures(args.json, result)


if __name__ == "__main__":
    main()
