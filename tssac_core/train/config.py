"""A training run's settings: `TrainConfig`, and the learner configs built from them (the algorithms' table:
:mod:`tssac_core.train.algorithms`)."""

from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tssac_core.algos.onpolicy.config import OnPolicyConfig
from tssac_core.algos.sac_config import SacConfig
from tssac_core.common.cli import SEED_MAX, UsageError
from tssac_core.common.errors import MAX_ACTION_REPEAT
from tssac_core.common.options import OptionError, check_fields, option
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.reward import RewardConfig
from tssac_core.sim.routes import RouteConfig
from tssac_core.sim.scenario import DEFAULT_SCENARIO, ROLES, Scenario
from tssac_core.train.algorithms import ALGORITHMS, Algo, Family, Selection, algorithm


def _roles_problem(roles: tuple[str, ...]) -> str | None:
    """The curriculum's roles, known and in order (Algorithm 1)."""
    known = [r.value for r in ROLES]
    for role in roles:
        if role not in known:
            return f"unknown role {role!r} (the roles: {', '.join(known)})"
    if not roles:
        return "name one or more roles"
    if list(roles) != [r for r in known if r in roles]:
        return f"must follow the curriculum order {', '.join(known)}"
    return None


def _roles(text: str) -> tuple[str, ...]:
    """``--roles decoy,detect``: comma-separated."""
    return tuple(r.strip() for r in text.split(",") if r.strip())


def _path(text: str) -> str:
    """A path as the command writes it ("" stays: none)."""
    return str(Path(text)) if text else ""


class TrainMonitor(enum.StrEnum):
    """``--train-monitor``: whether the training worlds fly through the runtime-assurance monitor."""

    OFF = "off"
    ON = "on"
    """tssac_core.sim.role_task.MonitorInTraining: a step the monitor flies instead of the learner costs 1."""
    SHIELD = "shield"
    """The same monitor, its steps costing only what the step flown costs (a shield in the learner's world)."""


@dataclass(frozen=True)
class TrainConfig:
    """One training run: an algorithm, a seed, the role curriculum. Each field's option (help, range, choices) is
    its flag of ``python -m tssac_core.train``, its key in a preset, a grid row and a run's config.json
    (tssac_core.common.options); the rules between fields are `__post_init__`'s."""

    algo: Algo = option(
        Algo.TSSAC,
        "learner; tssac: SAC-Lagrangian with the damped multiplier and transfer (tssac_core.train.algorithms)",
        choices=tuple(ALGORITHMS),
    )
    scenario: str = option(
        str(DEFAULT_SCENARIO), "scenario file (random layouts: every episode a new one, section 5.2.3)", parse=_path
    )
    seed: int = option(0, "seed of networks, layouts and exploration", minimum=0, maximum=SEED_MAX)
    epochs: int = option(50, "epochs per role (Table 3: 50)", minimum=1)
    steps_per_epoch: int = option(
        4000, "learner decisions per epoch, summed over the parallel worlds (Table 3: 4000)", minimum=1
    )
    roles: tuple[str, ...] = option(
        ("decoy", "detect", "strike"),
        "comma-separated, in curriculum order; earlier roles must already be in --out (or in --teammates)",
        rule=_roles_problem,
        parse=_roles,
    )
    envs: int = option(4, "parallel worlds collecting experience (one batched world)", minimum=1)
    update_every: int = option(1, "one gradient update per this many decisions (1: Algorithm 1)", minimum=1)
    start_steps: int = option(
        4000, "uniform random actions for this many decisions first (from-scratch roles, not after transfer)", minimum=0
    )
    update_after: int = option(1000, "no updates before the buffer holds this many transitions", minimum=0)
    observation: ObservationMode = option(
        ObservationMode.ROUTE,
        "observation: paper (eq. 7), extended, or route (extended + the way around the radars)",
        choices=tuple(m.value for m in ObservationMode),
    )
    action_repeat: int = option(
        1,
        "decision interval: hold each action for this many 0.1 s world steps (1: the paper)",
        minimum=1,
        maximum=MAX_ACTION_REPEAT,
    )
    penalty: float = option(0.0, "sac_penalty: reward r + penalty * c (e.g. -10)")
    threads: int = option(1, "torch threads (whatever the machine: runs beside each other want a core each)", minimum=1)
    """1 by default: at Table 3's sizes a second thread gains little (benchmarks/RESULTS.md), and runs beside each
    other (the grid's jobs, ``--seeds``) each want one core."""
    route_margin_km: float = option(
        3.0, "reward and route observation: the way to the zone keeps this far from the radars", minimum=0
    )
    cost_margin_km: float = option(
        1.0, "the learner's cost counts steps within this distance of a radar (0: eq. 11 exactly)", minimum=0
    )
    """A tightened constraint, so that the policy keeps clear of the radars' edges (docs/decisions.md). Evaluation,
    validation and the hazard_cost column count eq. 11 exactly."""
    hard_layouts: float = option(
        0.0,
        "draw this share of training episodes from hard layouts only (0: the scenario's own draw; validation and "
        "evaluation keep it)",
        minimum=0,
        maximum=1,
        metavar="FRACTION",
    )
    hard_detour_km: float = option(
        20.0,
        "hard layout: some UAV's way around the radars is this much longer than the straight line",
        minimum=0,
    )
    validation_episodes: int = option(
        30, "held-out missions flown after every epoch to pick the shipped one (0: ship the last epoch)", minimum=0
    )
    init_from: str = option(
        "",
        "initialise the learner of every trained role from this role checkpoint, or each from its own checkpoint in "
        "this team's directory, e.g. models/tssac (fine-tuning; the SAC family)",
        parse=_path,
    )
    teammates: str = option(
        "",
        "directory whose trained earlier roles fly beside (and, for tssac, transfer to) the trained roles, e.g. "
        "models/tssac with --roles strike (default: --out itself)",
        parse=_path,
    )
    stop_at_task_success: float = option(
        0.0,
        "end a role after the first epoch whose task success in training reaches this (e.g. 0.9; 0: never)",
        minimum=0,
        maximum=1,
        metavar="FRACTION",
    )
    """For measuring how many decisions a role needs to reach a level, as the transfer experiment does."""
    airframe_response: str = option(
        "",
        "train on airframes varied per episode within this fitted response's spans (turn lag, achievable "
        "acceleration; e.g. sim_vehicles/dynamics/airframes/f16.response.yaml; none: eq. 5-6 exactly)",
        parse=_path,
        metavar="FILE",
    )
    """tssac_core.sim.varied_airframes; validation and evaluation fly eq. 5-6 exactly either way."""
    vary_wind_m_s: float = option(
        0.0, "with --airframe-response: a constant wind per episode, up to this speed (m/s)", minimum=0, maximum=50
    )
    vary_turn_noise_deg_s: float = option(
        0.0,
        "with --airframe-response: turbulence, a heading-rate disturbance of this standard deviation (deg/s)",
        minimum=0,
        maximum=90,
    )
    vary_nominal_fraction: float = option(
        0.0,
        "with --airframe-response: this share of the training worlds flies eq. 5-6 exactly each episode (no lag, "
        "the scenario's acceleration, no wind), the rest the varied airframes",
        minimum=0,
        maximum=1,
        metavar="FRACTION",
    )
    train_monitor: TrainMonitor = option(
        TrainMonitor.OFF,
        "on: every training UAV flies through the runtime-assurance monitor (adjusted; with --airframe-response "
        "predicting with each airframe's lag, in wind ending in the ground loiter), and a step it flies instead of "
        "the learner costs 1 like a step in a radar (tssac_core.sim.role_task.MonitorInTraining); shield: the same "
        "monitor, its steps costing only what the step flown costs",
        choices=tuple(TrainMonitor),
    )
    train_monitor_margin_m: float = option(
        100.0, "with --train-monitor on: the clearance its paths keep from radars and edges (m)", minimum=0
    )
    """A companion's monitor adds its estimate's error bound to the margin (under JSBSim in wind up to about 1 km);
    the training's sees the true state."""
    selection: Selection | None = option(
        None,
        "which validated epoch a role ships: the best mission success among the epochs within the cost limit "
        "(within_limit: default of tssac, sac_lag, ppo_lag, cpo), or whatever the cost (success: default of sac, "
        "sac_penalty, ppo), or tail: screen every epoch on the upper bound of its cost and its within-C fraction, "
        "and choose among the best three on more missions (tssac_core.train.validation)",
        choices=tuple(Selection),
    )
    learner: dict[str, Any] = field(default_factory=dict)
    """Overrides of the learner's settings (``--set``): SacConfig fields for the off-policy family (Table 3
    defaults), OnPolicyConfig fields for the on-policy one."""

    def __post_init__(self) -> None:
        check_fields(self)
        # Words from the command line or a config.json become their enums.
        object.__setattr__(self, "algo", Algo(self.algo))
        object.__setattr__(self, "selection", Selection(self.selection) if self.selection else None)
        object.__setattr__(self, "train_monitor", TrainMonitor(self.train_monitor))
        object.__setattr__(self, "observation", ObservationMode(self.observation))
        object.__setattr__(self, "roles", tuple(self.roles))
        # The rules between fields.
        varies = ("vary_wind_m_s", "vary_turn_noise_deg_s", "vary_nominal_fraction")
        varied = next((name for name in varies if getattr(self, name)), None)
        if varied and not self.airframe_response:
            raise OptionError(varied, "varies the airframes of airframe_response (--airframe-response): give it too")
        if self.penalty != 0.0 and self.algo != Algo.SAC_PENALTY:
            raise OptionError("penalty", f"only sac_penalty takes a penalty, not {self.algo}")
        if self.init_from and algorithm(self.algo).family is Family.ON_POLICY:
            raise OptionError(
                "init_from", f"{self.algo} trains every role from scratch (the SAC family can be initialised)"
            )


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
