"""A training run's settings: `TrainConfig`, and the learner configs built from them (the algorithms' table:
:mod:`tssac_core.train.algorithms`)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from tssac_core.algos.onpolicy.config import OnPolicyConfig
from tssac_core.algos.sac_config import SacConfig
from tssac_core.common.cli import UsageError
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.reward import RewardConfig
from tssac_core.sim.routes import RouteConfig
from tssac_core.sim.scenario import DEFAULT_SCENARIO, Scenario
from tssac_core.train.algorithms import Algo, Family, Selection, algorithm


@dataclass(frozen=True)
class TrainConfig:
    """One training run: an algorithm, a seed, the role curriculum."""

    algo: Algo = Algo.TSSAC
    """The algorithm (tssac_core.train.algorithms: its family, whether it is constrained, whether it transfers)."""
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
    observation: ObservationMode = ObservationMode.ROUTE
    """paper (eq. 7), extended, or route (extended + the way around the radars; tssac_core.sim.observation)."""
    action_repeat: int = 1
    """Decision interval: the learner's action is held for this many 0.1 s world steps (1: the paper)."""
    penalty: float = 0.0
    """sac_penalty: reward r + penalty * c."""
    threads: int = 1
    """torch threads. 1 by default, whatever the machine: at Table 3's sizes a second thread gains little
    (benchmarks/RESULTS.md), and runs beside each other (the grid's jobs, ``--seeds``) each want one core."""
    route_margin_km: float = 3.0
    """Reward: the way around the radars keeps this far from them (tssac_core.sim.routes.RouteConfig)."""
    cost_margin_km: float = 1.0
    """The learner's cost counts steps within this distance of a radar, not only inside it: a tightened
    constraint, so that the policy keeps clear of the radars' edges (docs/decisions.md). Evaluation,
    validation and the hazard_cost column count eq. 11 exactly."""
    hard_layouts: float = 0.0
    """Share of training episodes drawn from hard layouts only (tssac_core.sim.hard_layouts; 0: the scenario's
    own draw). Validation and evaluation keep the scenario's own draw."""
    hard_detour_km: float = 20.0
    """A layout is hard when some UAV's way around the radars is at least this much longer than the straight line."""
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
    airframe_response: str = ""
    """Train on varied airframes (tssac_core.sim.varied_airframes): the turn lag and achievable acceleration drawn per
    episode from the spans of this fitted response file (e.g. sim_vehicles/dynamics/airframes/f16.response.yaml). ""
    (default): eq. 5-6 exactly. Validation and evaluation fly eq. 5-6 exactly either way."""
    vary_wind_m_s: float = 0.0
    """With ``airframe_response``: a constant wind per episode, its speed drawn up to this (m/s)."""
    vary_turn_noise_deg_s: float = 0.0
    """With ``airframe_response``: turbulence, a heading-rate disturbance per step of this standard deviation
    (deg/s)."""
    selection: Selection | None = None
    """Which validated epoch a role ships (tssac_core.train.algorithms.Selection, tssac_core.train.validation);
    None: the algorithm's own (Algorithm.default_selection): within the limit for the learners that are given
    it, by success for those that are not (sac, sac_penalty, ppo)."""
    learner: dict[str, Any] = field(default_factory=dict)
    """Overrides of the learner's settings (``--set``): SacConfig fields for the off-policy family (Table 3
    defaults), OnPolicyConfig fields for the on-policy one."""

    def __post_init__(self) -> None:
        # Words from the command line or a config.json become their enums (ValueError for a word that is none).
        object.__setattr__(self, "algo", Algo(self.algo))
        object.__setattr__(self, "selection", Selection(self.selection) if self.selection else None)
        object.__setattr__(self, "observation", ObservationMode(self.observation))


def has_multiplier_signal(algo: str) -> bool:
    """An off-policy algorithm with a learned multiplier (its SacConfig.multiplier_signal matters)."""
    a = algorithm(algo)
    return a.family is Family.OFF_POLICY and a.constrained


def selection_of(cfg: TrainConfig) -> Selection:
    """TrainConfig.selection, resolved."""
    return cfg.selection or algorithm(cfg.algo).default_selection


def selects_within_limit(cfg: TrainConfig) -> bool:
    """Whether the run ships the best epoch within the cost limit (TrainConfig.selection, resolved)."""
    return selection_of(cfg) is Selection.WITHIN_LIMIT


def default_selection(algo: str) -> Selection:
    """TrainConfig.selection's default: a learner that is not given the cost limit is not judged by it either."""
    return algorithm(algo).default_selection


def with_recorded_defaults(cfg: TrainConfig) -> TrainConfig:
    """``cfg`` with the settings whose default changed written out, so that a run's config.json records
    which it used: TSSAC's and SAC-Lagrangian's multiplier_signal in ``learner`` ("q_c" before), and the
    epoch selection (every algorithm's was "within_limit" before)."""
    if has_multiplier_signal(cfg.algo) and "multiplier_signal" not in cfg.learner:
        cfg = dataclasses.replace(cfg, learner={**cfg.learner, "multiplier_signal": SacConfig.multiplier_signal})
    if not cfg.selection:
        cfg = dataclasses.replace(cfg, selection=default_selection(cfg.algo))
    return cfg


def config_record(cfg: TrainConfig) -> dict[str, Any]:
    """What a run's config.json holds for ``cfg``: every field, the changed defaults written out
    (`with_recorded_defaults`), as JSON values (roles a list). `tssac_core.train.legacy.config_from_saved` reads it
    back into the same TrainConfig."""
    recorded = with_recorded_defaults(cfg)
    return {**dataclasses.asdict(recorded), "roles": list(recorded.roles)}


def reward_config(cfg: TrainConfig) -> RewardConfig:
    return RewardConfig(route=RouteConfig(margin_m=cfg.route_margin_km * 1000.0))


def sac_config(cfg: TrainConfig, scenario: Scenario) -> SacConfig:
    # The learner's episode is counted in decisions: the Q^c limit converts C over that many.
    decisions = math.ceil(scenario.episode_steps / cfg.action_repeat)
    variant = algorithm(cfg.algo).variant
    if variant is None:
        raise ValueError(f"not an off-policy algorithm: {cfg.algo!r}")
    fields: dict[str, Any] = {"variant": variant, "cost_limit": scenario.cost_limit, "episode_steps": decisions}
    if cfg.algo == "sac_penalty":
        fields["penalty"] = cfg.penalty
    fields.update(cfg.learner)
    if "hidden_sizes" in fields:
        fields["hidden_sizes"] = tuple(fields["hidden_sizes"])
    return SacConfig(**fields)


def onpolicy_config(cfg: TrainConfig, scenario: Scenario) -> OnPolicyConfig:
    """The OnPolicyConfig of a run: algorithm, C and the episode cap from the scenario, then ``cfg.learner``'s
    overrides (ValueError naming the key for one that OnPolicyConfig does not have)."""
    onpolicy = algorithm(cfg.algo).onpolicy
    if onpolicy is None:
        raise ValueError(f"not an on-policy algorithm: {cfg.algo!r}")
    names = {f.name for f in dataclasses.fields(OnPolicyConfig)} - {"algo"}
    for key in cfg.learner:
        if key not in names:
            raise ValueError(f"unknown OnPolicyConfig field {key!r}")
    # The learner's episode is counted in decisions (as sac_config does for the Q^c limit).
    fields: dict[str, Any] = {
        "algo": onpolicy,
        "cost_limit": scenario.cost_limit,
        "episode_steps": math.ceil(scenario.episode_steps / cfg.action_repeat),
    }
    fields.update(cfg.learner)
    fields["hidden_sizes"] = tuple(fields.get("hidden_sizes", OnPolicyConfig.hidden_sizes))
    return OnPolicyConfig(**fields)


def check_learner_settings(cfg: TrainConfig, scenario: Scenario) -> None:
    """Build the algorithm's config once, so that a bad --set fails before any work, in one line."""
    if cfg.init_from and algorithm(cfg.algo).family is Family.ON_POLICY:
        raise UsageError(f"--init-from: {cfg.algo} trains every role from scratch (the SAC family can be initialised)")
    try:
        if algorithm(cfg.algo).family is Family.ON_POLICY:
            check_override_kinds(cfg.learner, OnPolicyConfig)
            onpolicy_config(cfg, scenario)
        else:
            check_override_kinds(cfg.learner, SacConfig)
            for key in cfg.learner:
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
