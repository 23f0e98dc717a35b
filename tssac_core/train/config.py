"""A training run's settings: `TrainConfig`, the algorithms, and the learner configs built from them."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tssac_core.algos.onpolicy.ppo import OnPolicyAlgo, OnPolicyConfig
from tssac_core.algos.sac_lagrangian import MULTIPLIER_VARIANTS, SacConfig, Variant
from tssac_core.cli import UsageError
from tssac_core.sim.reward import RewardConfig
from tssac_core.sim.routes import RouteConfig
from tssac_core.sim.scenario import Scenario

DEFAULT_SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "random.yaml"
SAC_FAMILY = {v.value: v for v in Variant}
ON_POLICY = ("ppo", "ppo_lag", "cpo")
ALGOS = (*SAC_FAMILY, *ON_POLICY)
ONPOLICY_ALGOS = {a.value: a for a in OnPolicyAlgo}


@dataclass(frozen=True)
class TrainConfig:
    """One training run: an algorithm, a seed, the role curriculum."""

    algo: str = "tssac"
    """tssac, sac_lag, sac, sac_penalty (off-policy, tssac_core.algos.sac_lagrangian) or ppo, ppo_lag, cpo
    (on-policy, tssac_core.train.onpolicy_loop)."""
    scenario: str = str(DEFAULT_SCENARIO)
    """Scenario file (random layouts: every episode a new one, section 5.2.3)."""
    seed: int = 0
    epochs: int = 50
    """Epochs per role (Table 3: 50)."""
    steps_per_epoch: int = 4000
    """Environment steps per epoch, summed over the parallel worlds (Table 3: 4,000)."""
    roles: tuple[str, ...] = ("decoy", "detect", "strike")
    """Roles to train, in curriculum order; earlier roles must already be in --out (or in ``teammates``)."""
    envs: int = 4
    """Parallel worlds collecting experience (one batched world)."""
    update_every: int = 1
    """Gradient updates happen once per this many environment steps (1: one update per step, as Algorithm 1)."""
    start_steps: int = 4000
    """From-scratch roles act uniformly at random for this many steps first (not after transfer)."""
    update_after: int = 1000
    """No updates before the buffer holds this many transitions."""
    observation: str = "route"
    """paper (eq. 7), extended, or route (extended + the way around the radars; tssac_core.sim.observation)."""
    action_repeat: int = 1
    """Decision interval: the learner's action is held for this many 0.1 s world steps (1: the paper)."""
    penalty: float = 0.0
    """sac_penalty: reward r + penalty * c."""
    threads: int = 2
    """torch threads (this machine has 2 cores)."""
    route_margin_km: float = 3.0
    """Reward: the way around the radars keeps this far from them (tssac_core.sim.routes.RouteConfig)."""
    cost_margin_km: float = 1.0
    """The learner's cost counts steps within this distance of a radar, not only inside it: a tightened
    constraint, so that the policy keeps clear of the radars' edges (docs/decisions.md). Evaluation,
    validation and the hazard_cost column count eq. 11 exactly."""
    validation_episodes: int = 30
    """After every epoch, fly this many held-out missions with the greedy policy; the best epoch is shipped
    (tssac_core.train.validation). 0: ship the last epoch."""
    init_from: str = ""
    """A role checkpoint whose networks initialise every trained role (fine-tuning; transfer() resets the rest)."""
    teammates: str = ""
    """A directory of trained role checkpoints (a run, or ``models/tssac``) for the earlier roles this run does
    not train: they fly beside the trained roles and, for TSSAC, are transferred from. "" (default): this
    run's own --out (the curriculum)."""
    stop_at_task_success: float = 0.0
    """End a role after the first epoch whose task success in training reaches this fraction (0: train every
    epoch). For measuring how many decisions a role needs to reach a level, as the transfer experiment does."""
    selection: str = ""
    """Which validated epoch a role ships (tssac_core.train.validation): "within_limit", the best mission success
    among the epochs within the cost limit; "success", the best mission success whatever the cost; "tail", the
    tail-aware selection (the upper bound of the role's cost within the limit, then success, judged again on more
    missions among the best three; for validation on hundreds of missions). "" (the
    default): the algorithm's own, "within_limit" for the learners that are given the limit
    (CONSTRAINED_ALGOS), "success" for those that are not (sac, sac_penalty, ppo)."""
    sac: dict[str, Any] = field(default_factory=dict)
    """Overrides of SacConfig fields (Table 3 defaults)."""


SAC_MULTIPLIER_ALGOS = tuple(algo for algo, variant in SAC_FAMILY.items() if variant in MULTIPLIER_VARIANTS)
"""The SAC family's algorithms with a learned multiplier (SacConfig.multiplier_signal matters)."""

CONSTRAINED_ALGOS = (*SAC_MULTIPLIER_ALGOS, "ppo_lag", "cpo")
"""The learners that are given the cost limit C: they ship the best epoch within it (TrainConfig.selection)."""
SELECTIONS = ("within_limit", "success", "tail")


def selects_within_limit(cfg: TrainConfig) -> bool:
    """Whether the run ships the best epoch within the cost limit (TrainConfig.selection, resolved)."""
    return (cfg.selection or default_selection(cfg.algo)) == "within_limit"


def default_selection(algo: str) -> str:
    """TrainConfig.selection's default: a learner that is not given the cost limit is not judged by it either."""
    return "within_limit" if algo in CONSTRAINED_ALGOS else "success"


def with_recorded_defaults(cfg: TrainConfig) -> TrainConfig:
    """``cfg`` with the settings whose default changed written out, so that a run's config.json records
    which it used: TSSAC's and SAC-Lagrangian's multiplier_signal in ``sac`` ("q_c" before), and the
    epoch selection (every algorithm's was "within_limit" before)."""
    if cfg.algo in SAC_MULTIPLIER_ALGOS and "multiplier_signal" not in cfg.sac:
        cfg = dataclasses.replace(cfg, sac={**cfg.sac, "multiplier_signal": SacConfig.multiplier_signal})
    if not cfg.selection:
        cfg = dataclasses.replace(cfg, selection=default_selection(cfg.algo))
    return cfg


def reward_config(cfg: TrainConfig) -> RewardConfig:
    return RewardConfig(route=RouteConfig(margin_m=cfg.route_margin_km * 1000.0))


def sac_config(cfg: TrainConfig, scenario: Scenario) -> SacConfig:
    # The learner's episode is counted in decisions: the Q^c limit converts C over that many.
    decisions = math.ceil(scenario.episode_steps / cfg.action_repeat)
    fields = {"variant": SAC_FAMILY[cfg.algo], "cost_limit": scenario.cost_limit, "episode_steps": decisions}
    if cfg.algo == "sac_penalty":
        fields["penalty"] = cfg.penalty
    fields.update(cfg.sac)
    if "hidden_sizes" in fields:
        fields["hidden_sizes"] = tuple(fields["hidden_sizes"])
    return SacConfig(**fields)


def onpolicy_config(cfg: TrainConfig, scenario: Scenario) -> OnPolicyConfig:
    """The OnPolicyConfig of a run: algorithm, C and the episode cap from the scenario, then ``cfg.sac``'s
    overrides (ValueError naming the key for one that OnPolicyConfig does not have)."""
    if cfg.algo not in ONPOLICY_ALGOS:
        raise ValueError(f"not an on-policy algorithm: {cfg.algo!r} (choose from {', '.join(ONPOLICY_ALGOS)})")
    names = {f.name for f in dataclasses.fields(OnPolicyConfig)} - {"algo"}
    for key in cfg.sac:
        if key not in names:
            raise ValueError(f"unknown OnPolicyConfig field {key!r}")
    # The learner's episode is counted in decisions (as sac_config does for the Q^c limit).
    fields: dict[str, Any] = {
        "algo": ONPOLICY_ALGOS[cfg.algo],
        "cost_limit": scenario.cost_limit,
        "episode_steps": math.ceil(scenario.episode_steps / cfg.action_repeat),
    }
    fields.update(cfg.sac)
    fields["hidden_sizes"] = tuple(fields.get("hidden_sizes", OnPolicyConfig.hidden_sizes))
    return OnPolicyConfig(**fields)


def check_learner_settings(cfg: TrainConfig, scenario: Scenario) -> None:
    """Build the algorithm's config once, so that a bad --set fails before any work, in one line."""
    try:
        if cfg.algo in ON_POLICY:
            check_override_kinds(cfg.sac, OnPolicyConfig)
            onpolicy_config(cfg, scenario)
        else:
            check_override_kinds(cfg.sac, SacConfig)
            for key in cfg.sac:
                if key not in {f.name for f in dataclasses.fields(SacConfig)} or key == "variant":
                    raise ValueError(f"unknown SacConfig field {key!r}")
            sac_config(cfg, scenario)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"invalid learner settings (--set): {exc}") from None


def check_override_kinds(overrides: dict[str, Any], config: type) -> None:
    """A word (``--set key=word``) only for a setting that is a word, such as multiplier_signal, and a
    number, list or boolean for every other: ValueError naming the key."""
    words = {f.name for f in dataclasses.fields(config) if isinstance(f.default, str)}
    for key, value in overrides.items():
        if isinstance(value, str) != (key in words):
            expected = "a word" if key in words else "a number, list or boolean"
            raise ValueError(f"{key}: expected {expected}, got {value!r}")
