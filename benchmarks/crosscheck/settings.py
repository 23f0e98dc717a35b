"""What the cross-check trains and how: the algorithms on both sides, the budget, the settings both sides share
(read from our recipe, configs/paper.yaml), the training commands, and OmniSafe's ``custom_cfgs``.

Pure: no torch, no OmniSafe, no simulation. Both sides train the detect role beside the shipped decoy
(models/tssac) on the random scenario, one decision per 1 s (action_repeat 10), for ``epochs x steps_per_epoch``
decisions, and ship the last epoch (ours with ``--validation-episodes 0``: OmniSafe has no held-out selection).

OmniSafe keeps its own defaults (its configs/<type>/<Algo>.yaml) except what defines the problem or the budget,
``ALIGNED`` below; every other setting is OmniSafe's, and the differences are listed in
benchmarks/crosscheck/README.md.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
PRESET = ROOT / "configs" / "paper.yaml"
SCENARIO = ROOT / "scenarios" / "random.yaml"
TEAMMATES = ROOT / "models" / "tssac"
ROLE = "detect"
ENV_ID = "TssacDetect-v0"

ALGOS: dict[str, str] = {"cpo": "CPO", "ppo_lag": "PPOLag", "sac_lag": "SACLag"}
"""Our algorithm -> OmniSafe's."""
IMPLS = ("ours", "omnisafe")
OFF_POLICY = ("sac_lag",)

EVAL_SEED = 2600001
"""Mission k of the evaluation flies the layout drawn from seed EVAL_SEED + k (tssac_core.sim.missions): a seed
range used for nothing else (training layouts come from seed * 1000 + role on our side, OmniSafe's seed + world
on its side; the grid's evaluations use 12345, 990001, 2200001-2260001, 2400001, 2500001)."""
EVAL_EPISODES = 200

OMNISAFE_WARMUP_SHARE = 0.2
"""OmniSafe's SACLag leaves its multiplier alone for ``warmup_epochs`` (100 of its default 500 epochs of 2,000
steps, a fifth of training); at our 50 or fewer epochs 100 would mean never. The cross-check keeps the fifth."""

ALIGNED = (
    "budget: total_steps = epochs x steps_per_epoch decisions, steps_per_epoch, one world (vector_env_nums 1), "
    "one torch thread",
    "problem: the detect role beside the shipped decoy, random layouts, route observation, action_repeat 10, "
    "cost = world steps (0.1 s) within cost_margin_km of a radar, summed per episode, limit C per episode",
    "episode ends: only a hit stops bootstrapping; leaving the area and the cap truncate (leaving_terminates false), "
    "as our learners treat them (docs/decisions.md)",
    "discount: gamma (and cost_gamma) as our recipe's",
    "networks: actor and critic hidden sizes as our recipe's (activations stay OmniSafe's)",
    "SACLag: one update per update_every decisions (update_cycle), first update after update_after decisions "
    "(start_learning_steps), multiplier warm-up a fifth of the epochs (warmup_epochs), no per-epoch test episode",
)


class SettingsError(ValueError):
    """A bad setting (the command prints it as one line)."""


@dataclass(frozen=True)
class Budget:
    """Training decisions of 1 s: ``epochs`` x ``steps_per_epoch``."""

    epochs: int
    steps_per_epoch: int

    def __post_init__(self) -> None:
        if self.epochs < 1 or self.steps_per_epoch < 1:
            raise SettingsError(f"epochs and steps per epoch must be >= 1, got {self.epochs} x {self.steps_per_epoch}")

    @property
    def decisions(self) -> int:
        return self.epochs * self.steps_per_epoch


@dataclass(frozen=True)
class Job:
    """One training run: an implementation, an algorithm (our name), a seed."""

    impl: str
    algo: str
    seed: int

    def __post_init__(self) -> None:
        if self.impl not in IMPLS:
            raise SettingsError(f"implementation must be one of {', '.join(IMPLS)}, got {self.impl!r}")
        if self.algo not in ALGOS:
            raise SettingsError(f"algorithm must be one of {', '.join(ALGOS)}, got {self.algo!r}")
        if self.seed < 0:
            raise SettingsError(f"seed must be >= 0, got {self.seed}")

    @property
    def name(self) -> str:
        return f"{self.impl}-{self.algo}-seed{self.seed}"


@dataclass(frozen=True)
class Shared:
    """The settings both sides train with (our recipe's; ``shared_settings`` reads them)."""

    cost_limit: float
    """C per episode, in world steps of 0.1 s (scenario's cost_limit)."""
    cost_margin_km: float
    """The learner's cost counts steps within this distance of a radar (TrainConfig.cost_margin_km)."""
    gamma: float
    hidden_sizes: tuple[int, ...]
    action_repeat: int
    update_every: int
    update_after: int


def shared_settings(preset: dict[str, Any], cost_limit: float, cost_margin_km: float = 1.0) -> Shared:
    """The shared settings from our recipe (configs/paper.yaml as a dict): the on-policy and the SAC family's
    network sizes and discounts must agree, since one OmniSafe configuration per algorithm follows them."""
    onp, sac = preset.get("onpolicy_set", {}), preset.get("sac_set", {})
    gamma, hidden = onp.get("gamma"), onp.get("hidden_sizes")
    if gamma is None or hidden is None or sac.get("gamma") != gamma or sac.get("hidden_sizes") != hidden:
        raise SettingsError("the recipe must give both families the same gamma and hidden_sizes")
    return Shared(
        cost_limit=float(cost_limit),
        cost_margin_km=float(preset.get("cost_margin_km", cost_margin_km)),
        gamma=float(gamma),
        hidden_sizes=tuple(int(h) for h in hidden),
        action_repeat=int(preset["action_repeat"]),
        update_every=int(preset["update_every"]),
        update_after=int(preset["update_after"]),
    )


def ours_command(python: str, job: Job, budget: Budget, out: Path, resume: bool = False) -> list[str]:
    """Our training command for ``job``: the recipe, the detect role only, beside the shipped decoy, the last
    epoch shipped."""
    cmd = [
        python, "-m", "tssac_core.train",
        "--preset", str(PRESET),
        "--algo", job.algo,
        "--roles", ROLE,
        "--teammates", str(TEAMMATES),
        "--epochs", str(budget.epochs),
        "--steps-per-epoch", str(budget.steps_per_epoch),
        "--seed", str(job.seed),
        "--validation-episodes", "0",
        "--no-progress",
        "--out", str(out),
    ]  # fmt: skip
    return [*cmd, "--resume"] if resume else cmd


def omnisafe_command(python: str, cfgs_file: Path, out: Path) -> list[str]:
    """The command that trains and exports OmniSafe's actor in OmniSafe's environment (benchmarks.crosscheck
    .omnisafe_side), from the ``custom_cfgs`` written to ``cfgs_file``."""
    return [python, "-m", "benchmarks.crosscheck.omnisafe_side", "--cfgs", str(cfgs_file), "--out", str(out)]


def omnisafe_cfgs(
    algo: str, budget: Budget, seed: int, shared: Shared, log_dir: Path, overrides: dict[str, Any] | None = None
) -> dict[str, Any]:
    """OmniSafe's ``custom_cfgs`` for our ``algo``: its defaults but for ``ALIGNED``, then ``overrides`` (dotted
    keys, e.g. ``{"algo_cfgs.update_iters": 10}``)."""
    if algo not in ALGOS:
        raise SettingsError(f"algorithm must be one of {', '.join(ALGOS)}, got {algo!r}")
    hidden = list(shared.hidden_sizes)
    cfgs: dict[str, Any] = {
        "seed": seed,
        "train_cfgs": {
            "device": "cpu",
            "total_steps": budget.decisions,
            "vector_env_nums": 1,
            "torch_threads": 1,
        },
        "algo_cfgs": {"steps_per_epoch": budget.steps_per_epoch, "gamma": shared.gamma},
        "model_cfgs": {"actor": {"hidden_sizes": hidden}, "critic": {"hidden_sizes": hidden}},
        "logger_cfgs": {
            "log_dir": str(log_dir),
            "use_wandb": False,
            "use_tensorboard": False,
            "save_model_freq": budget.epochs,  # the last epoch's actor is saved (off-policy saves no other)
        },
        "env_cfgs": {
            "scenario": str(SCENARIO),
            "observation": "route",
            "action_repeat": shared.action_repeat,
            "teammates": str(TEAMMATES),
            "teammate_roles": ["decoy"],
            "cost_margin_km": shared.cost_margin_km,
            "leaving_terminates": False,
        },
    }
    if algo in OFF_POLICY:
        cfgs["lagrange_cfgs"] = {"cost_limit": shared.cost_limit}
        cfgs["train_cfgs"]["eval_episodes"] = 0
        cfgs["algo_cfgs"].update(
            {
                "update_cycle": shared.update_every,
                "update_iters": 1,
                "start_learning_steps": shared.update_after,
                "warmup_epochs": math.floor(OMNISAFE_WARMUP_SHARE * budget.epochs),
            }
        )
    else:
        cfgs["algo_cfgs"]["cost_gamma"] = shared.gamma
        if algo == "cpo":
            cfgs["algo_cfgs"]["cost_limit"] = shared.cost_limit
        else:
            cfgs["lagrange_cfgs"] = {"cost_limit": shared.cost_limit}
    for key, value in (overrides or {}).items():
        set_dotted(cfgs, key, value)
    return cfgs


def set_dotted(cfgs: dict[str, Any], key: str, value: Any) -> None:
    """``cfgs[a][b] = value`` for ``key`` "a.b" (intermediate dicts made as needed)."""
    parts = key.split(".")
    if not all(parts):
        raise SettingsError(f"bad OmniSafe setting {key!r}: expected dotted keys such as algo_cfgs.update_iters")
    node = cfgs
    for part in parts[:-1]:
        child = node.setdefault(part, {})
        if not isinstance(child, dict):
            raise SettingsError(f"bad OmniSafe setting {key!r}: {part} is not a section")
        node = child
    node[parts[-1]] = value


def parse_override(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` with VALUE as JSON when it parses (numbers, lists, true/false), else the word."""
    key, sep, raw = text.partition("=")
    if not sep or not key:
        raise SettingsError(f"expected KEY=VALUE, got {text!r}")
    try:
        return key, json.loads(raw)
    except json.JSONDecodeError:
        return key, raw
