"""OmniSafe's side, run in OmniSafe's own environment (gymnasium 0.28.1): train one algorithm on TssacDetect-v0
from a ``custom_cfgs`` JSON (settings.omnisafe_cfgs), then export the last saved actor to ``OUT/actor.npz``
(actor_file) after checking that the numpy actor computes what OmniSafe's does, and write ``OUT/train.json``.

    PYTHONPATH=. $(python benchmarks/omnisafe_env.py) -m benchmarks.crosscheck.omnisafe_side --cfgs CFGS.json --out DIR

The driver (benchmarks/crosscheck_omnisafe.py) writes CFGS.json and runs this; the algorithm is the cfgs' "algo".
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.crosscheck.actor_file import OmniSafeActor, write_actor
from tssac_core.common.cli import command_description

EXPORT_TOLERANCE = 1e-4
"""Largest |numpy - torch| action difference accepted on the check's observations."""


def default_cfgs_with_env_section(get_default: Any) -> Any:
    """OmniSafe 0.5.0's off-policy yamls have no ``env_cfgs`` section, so its config check refuses custom
    ``env_cfgs`` ("Invalid key: env_cfgs") although its adapter reads them: add an empty one."""
    from omnisafe.utils.config import Config

    def patched(algo: str, env_id: str, algo_type: str) -> Any:
        cfgs = get_default(algo, env_id, algo_type)
        if "env_cfgs" not in cfgs:
            cfgs["env_cfgs"] = Config.dict2config({})
        return cfgs

    return patched


def last_checkpoint(log_dir: Path) -> Path:
    """The highest-numbered ``torch_save/epoch-<n>.pt`` under ``log_dir``."""
    found = [
        (int(m.group(1)), p) for p in log_dir.rglob("epoch-*.pt") if (m := re.fullmatch(r"epoch-(\d+)\.pt", p.name))
    ]
    if not found:
        raise FileNotFoundError(f"no torch_save/epoch-*.pt under {log_dir}")
    return max(found)[1]


def export(cfgs: Any, checkpoint: Path, out: Path) -> dict[str, Any]:
    """Rebuild the actor as OmniSafe's Evaluator does, write ``out`` and check it against ``predict``."""
    import torch
    from omnisafe.common.normalizer import Normalizer
    from omnisafe.models.actor.actor_builder import ActorBuilder

    from tssac_core.sim.observation import ObservationMode, observation_bounds

    params = torch.load(checkpoint, map_location="cpu")
    from gymnasium import spaces

    low, high = observation_bounds(ObservationMode.ROUTE)
    obs_space = spaces.Box(low, high, dtype=np.float32)
    act_space = spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
    model = cfgs["model_cfgs"]
    actor = ActorBuilder(
        obs_space=obs_space,
        act_space=act_space,
        hidden_sizes=list(model["actor"]["hidden_sizes"]),
        activation=model["actor"]["activation"],
        weight_initialization_mode=model["weight_initialization_mode"],
    ).build_actor(model["actor_type"])
    actor.load_state_dict(params["pi"])
    linears = [m for m in actor.modules() if isinstance(m, torch.nn.Linear)]
    layers = [(m.weight.detach().numpy(), m.bias.detach().numpy()) for m in linears]
    norm = None
    mean = std = None
    if cfgs["algo_cfgs"].get("obs_normalize", False):
        norm = Normalizer(shape=obs_space.shape, clip=5)
        norm.load_state_dict(params["obs_normalizer"])
        mean, std = norm._mean.numpy().astype(np.float64), norm._std.numpy().astype(np.float64)
    meta = {
        "algo": cfgs["algo"],
        "actor_type": model["actor_type"],
        "activation": model["actor"]["activation"],
        "act_dim": 2,
        "obs_clip": 5.0,
        "action_repeat": int(cfgs["env_cfgs"].get("action_repeat", 10)),
        "source": str(checkpoint),
    }
    write_actor(out, meta, layers, mean, std)
    # The check: random observations in the observation box, OmniSafe's normalise-then-predict, clipped as the
    # world clips, against the numpy actor.
    rng = np.random.default_rng(0)
    obs = rng.uniform(np.maximum(low, -10), np.minimum(high, 10), size=(256, len(low))).astype(np.float32)
    with torch.no_grad():
        x = torch.as_tensor(obs)
        if norm is not None:
            x = torch.clamp((x - norm._mean) / norm._std, -5, 5)  # normalize() without pushing the data
        ref = torch.clamp(actor.predict(x, deterministic=True), -1, 1).numpy()
    diff = float(np.abs(OmniSafeActor.load(out)(obs) - ref).max())
    if diff > EXPORT_TOLERANCE:
        raise RuntimeError(f"exported actor differs from OmniSafe's by {diff:.2e}")
    return {"checkpoint": str(checkpoint), "export_max_abs_diff": diff}


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    p.add_argument("--cfgs", type=Path, required=True, help="custom_cfgs JSON with 'algo' (settings.omnisafe_cfgs)")
    p.add_argument("--out", type=Path, required=True, help="run directory: actor.npz, train.json, OmniSafe's logs")
    args = p.parse_args(argv)
    try:
        custom = json.loads(args.cfgs.read_text())
        algo = custom.pop("algo")
        ablation = custom.pop("crosscheck", {})  # ours, not OmniSafe's: omnisafe_variants
    except (OSError, ValueError, KeyError) as exc:
        print(f"error: {args.cfgs}: not a custom_cfgs JSON with 'algo': {exc}", file=sys.stderr)
        return 2
    try:
        import omnisafe.algorithms.algo_wrapper as wrapper
    except ImportError:
        print(
            "error: omnisafe is not importable: run this with OmniSafe's python "
            "(python benchmarks/omnisafe_env.py prints it)",
            file=sys.stderr,
        )
        return 2
    import tssac_core.train.omnisafe_env  # noqa: F401  (registers TssacDetect-v0)

    wrapper.get_default_kwargs_yaml = default_cfgs_with_env_section(wrapper.get_default_kwargs_yaml)
    args.out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    from benchmarks.crosscheck.omnisafe_variants import VariantAgent, variant_of

    try:
        variant = variant_of(algo, ablation)
        agent = VariantAgent(variant or algo, algo, "TssacDetect-v0", custom)  # omnisafe.Agent for no variant
    except (KeyError, AssertionError, ValueError) as exc:
        print(f"error: OmniSafe refused the configuration: {exc}", file=sys.stderr)
        return 2
    ep_ret, ep_cost, ep_len = agent.learn()
    wall = time.perf_counter() - start
    cfgs = agent.cfgs
    checkpoint = last_checkpoint(Path(custom["logger_cfgs"]["log_dir"]))
    if checkpoint.name != f"epoch-{cfgs.train_cfgs.epochs}.pt":  # the logger names it by epochs finished
        print(f"error: the last saved actor is {checkpoint}, not the last epoch's", file=sys.stderr)
        return 1
    checked = export(cfgs, checkpoint, args.out / "actor.npz")
    record = {
        "algo": algo,
        "variant": variant,
        "train_wall_s": round(wall, 2),
        "final": {"EpRet": float(ep_ret), "EpCost": float(ep_cost), "EpLen": float(ep_len)},
        "omnisafe_cfgs": cfgs.todict(),
        **checked,
    }
    (args.out / "train.json").write_text(json.dumps(record, indent=2, default=str) + "\n")
    diff = checked["export_max_abs_diff"]
    print(f"trained {algo} in {wall:.0f} s; actor {args.out / 'actor.npz'} (export diff {diff:.1e})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
