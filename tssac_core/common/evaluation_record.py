"""One evaluation's figures as one typed record: what the batched evaluation (``python -m tssac_core.evaluate``, the
experiments' caches, ``experiments.targets``) and ``python -m mavlink_bridge.fly`` write, and what their reports read.

The JSON has the keys it always had (``success_rate``, ``success_interval95``, ``mean_cost``, ``mean_cost_interval95``,
``episodes``, ``mean_mission_time_s``, ``roles``, ``worst_missions``, with the monitor ``shield``, then what flew
where) and ``record_version``. A file without ``record_version`` was written before the record existed and is read as
version 1 (an old experiments cache may also lack the intervals and the per-role figures: None and empty here). A
figure a world cannot know is None: ``fly`` against a ``--connect`` vehicle has no truth log, so no cost; its JSON
keeps such top-level figures as explicit nulls, and leaves a role's unknown figures out.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, NotRequired, TypedDict

RECORD_VERSION = 1
"""The schema this module writes; it reads every version up to this one."""

Interval = tuple[float, float]
"""A 95% interval (low, high); a JSON list of two."""


class RecordError(ValueError):
    """A JSON object that is no evaluation record this version can read: one line saying what is wrong."""


@dataclass(frozen=True)
class RoleFigures:
    """One role's figures over the missions (None: not known in this world, left out of the JSON)."""

    mean_cost: float | None = None
    max_cost: float | None = None
    within_cost_limit: float | None = None
    """The fraction of its UAV-missions whose cost is within the scenario's C."""
    cvar95_cost: float | None = None
    task_success_rate: float | None = None
    left_area_rate: float | None = None
    mean_return: float | None = None
    latency_p50_ms: float | None = None
    """``fly``: the median of its companions' median control latency."""
    latency_p99_ms: float | None = None
    """``fly``: the largest of its companions' 99th-percentile control latency."""


@dataclass(frozen=True)
class WorstMission:
    """One of the costliest UAV-missions: fly it again with ``--seed <run seed> --mission <mission>``."""

    mission: int
    seed: int
    """Its layout's seed."""
    role: str
    cost: float


@dataclass(frozen=True)
class RoleMonitorFigures:
    """The batched world's monitor, one role."""

    interventions_per_mission: float
    backup_time_fraction: float


@dataclass(frozen=True)
class WorldMonitorFigures:
    """The runtime-assurance monitor in the batched world, counted per simulation step."""

    interventions_per_uav_mission: float
    max_interventions_per_uav_mission: int
    max_switches_per_uav_mission: int
    backup_time_fraction: float
    """The share of flight time under the backup."""
    unprotected_time_fraction: float
    """The share of flight time with no backup that the monitor could prove safe."""
    uav_missions_with_cost: int
    uavs_left_area: int
    roles: dict[str, RoleMonitorFigures]
    config: dict[str, object] | None = None
    """The monitor's settings (``ShieldConfig`` as a dict), when the writer states them."""
    adjusted_time_fraction: float = 0.0
    """The share of flight time under the monitor's adjusted action (``ShieldConfig.adjust``)."""
    held_time_fraction: float = 0.0
    """The share of flight time a backup's lead flew holding its line."""


@dataclass(frozen=True)
class SitlMonitorFigures:
    """The runtime-assurance monitor in ``fly``'s companions, counted per control step (None: no companion counted)."""

    uav_missions: int
    interventions_per_uav_mission: float | None
    max_interventions_per_uav_mission: int | None
    backup_time_fraction: float | None
    unprotected_time_fraction: float | None
    decisions: int
    resets: int
    max_margin_m: float | None
    """The largest margin a companion's monitor used (its estimate's error and timing on top of the configured one)."""
    uav_missions_with_cost: int | None
    uavs_left_area: int | None
    guarantee: bool = True
    """False: the world flies physics the monitor's bound does not cover (``scope`` says why)."""
    scope: str | None = None
    adjusted_time_fraction: float | None = None
    """The share of control steps under the monitor's adjusted action (None: not counted)."""
    held_time_fraction: float | None = None
    """The share of control steps a backup's lead flew holding its line (None: not counted)."""
    vehicle_limits: dict[str, dict[str, object] | None] | None = None
    """Per role, what its vehicle said it achieves (``ACHV_*``: turn_rate_max_deg_s, accel_max_m_s2, decel_max_m_s2),
    as its companion read it first; None for a role whose vehicle said nothing (None: not counted)."""


RecordedMonitor = WorldMonitorFigures | SitlMonitorFigures
"""The monitor's figures as the world that flew counted them: per simulation step, or per companion control step."""


@dataclass(frozen=True)
class BatchedRun:
    """What flew a batched evaluation, where."""

    controller: str
    """The models directory, the controller, or which policies in which roles."""
    scenario: str
    seed: int
    cost_limit: float


@dataclass(frozen=True)
class FlownDynamics:
    model: str
    aircraft: str


@dataclass(frozen=True)
class FlownWind:
    speed_m_s: float
    from_deg: float
    turbulence: str


@dataclass(frozen=True)
class SitlRun:
    """What flew a ``fly`` campaign, where, over which link and clock."""

    episodes_requested: int
    pilot: str
    setpoints: str
    scenario: str
    dynamics: FlownDynamics | None
    """None: the vehicles of ``--connect`` fly physics this side does not know."""
    wind: FlownWind | None
    seed: int
    clock: str
    cost_limit: float
    signing: bool


class WorstMissionJson(TypedDict):
    mission: int
    seed: int
    role: str
    cost: float


class RoleMonitorJson(TypedDict):
    interventions_per_mission: float
    backup_time_fraction: float


class WorldMonitorJson(TypedDict):
    """:class:`WorldMonitorFigures` in the JSON (``config`` only when stated)."""

    interventions_per_uav_mission: float
    max_interventions_per_uav_mission: int
    max_switches_per_uav_mission: int
    backup_time_fraction: float
    unprotected_time_fraction: float
    uav_missions_with_cost: int
    uavs_left_area: int
    roles: dict[str, RoleMonitorJson]
    config: NotRequired[dict[str, object]]
    adjusted_time_fraction: NotRequired[float]
    held_time_fraction: NotRequired[float]


class SitlMonitorJson(TypedDict):
    """:class:`SitlMonitorFigures` in the JSON."""

    uav_missions: int
    interventions_per_uav_mission: float | None
    max_interventions_per_uav_mission: int | None
    backup_time_fraction: float | None
    unprotected_time_fraction: float | None
    decisions: int
    resets: int
    max_margin_m: float | None
    uav_missions_with_cost: int | None
    uavs_left_area: int | None
    guarantee: bool
    scope: str | None
    adjusted_time_fraction: NotRequired[float | None]
    held_time_fraction: NotRequired[float | None]
    vehicle_limits: NotRequired[dict[str, dict[str, object] | None] | None]


class FlownDynamicsJson(TypedDict):
    model: str
    aircraft: str


class FlownWindJson(TypedDict):
    speed_m_s: float
    from_deg: float
    turbulence: str


class RunJson(TypedDict, total=False):
    """What flew, spread into the record's JSON: :class:`BatchedRun`'s fields, or :class:`SitlRun`'s."""

    controller: str
    episodes_requested: int
    pilot: str
    setpoints: str
    scenario: str
    dynamics: FlownDynamicsJson | None
    wind: FlownWindJson | None
    seed: int
    clock: str
    cost_limit: float
    signing: bool


class _ShieldJson(TypedDict, total=False):
    shield: WorldMonitorJson | SitlMonitorJson


class EvaluationRecordJson(RunJson):
    """:meth:`EvaluationRecord.to_json` (module docstring): the figures, with the monitor ``shield``, then what flew
    (:class:`RunJson`'s keys) and ``record_version``."""

    success_rate: float | None
    success_interval95: list[float] | None
    mean_cost: float | None
    mean_cost_interval95: list[float] | None
    episodes: int
    mean_mission_time_s: float | None
    roles: dict[str, dict[str, float]]
    """Per role, its known figures (:class:`RoleFigures`' fields that are not None)."""
    worst_missions: list[WorstMissionJson]
    shield: NotRequired[WorldMonitorJson | SitlMonitorJson]
    record_version: int


@dataclass(frozen=True)
class EvaluationRecord:
    """M missions' figures, with 95% intervals: the Wilson score interval of the success rate and the bootstrap
    interval over missions of the mean cost per UAV (:mod:`tssac_core.common.stats`)."""

    success_rate: float | None
    success_interval95: Interval | None
    mean_cost: float | None
    """Hazard cost per UAV per mission."""
    mean_cost_interval95: Interval | None
    episodes: int
    mean_mission_time_s: float | None
    roles: dict[str, RoleFigures] = field(default_factory=dict)
    worst_missions: list[WorstMission] = field(default_factory=list)
    monitor: RecordedMonitor | None = None
    run: BatchedRun | SitlRun | None = None
    """What flew the missions, where (None: the figures alone)."""

    def with_monitor_config(self, config: Mapping[str, object]) -> EvaluationRecord:
        """This record with the monitor's settings stated (the batched world's monitor only)."""
        assert isinstance(self.monitor, WorldMonitorFigures), "the batched world's monitor states its settings"
        return dataclasses.replace(self, monitor=dataclasses.replace(self.monitor, config=dict(config)))

    def to_json(self) -> EvaluationRecordJson:
        """The JSON object, its keys in the order the files have always had them."""
        shield: _ShieldJson = {}
        if self.monitor is not None:
            shield["shield"] = _monitor_json(self.monitor)
        return {
            "success_rate": self.success_rate,
            "success_interval95": _interval_json(self.success_interval95),
            "mean_cost": self.mean_cost,
            "mean_cost_interval95": _interval_json(self.mean_cost_interval95),
            "episodes": self.episodes,
            "mean_mission_time_s": self.mean_mission_time_s,
            "roles": {role: _known(fig) for role, fig in self.roles.items()},
            "worst_missions": [
                {"mission": w.mission, "seed": w.seed, "role": w.role, "cost": w.cost} for w in self.worst_missions
            ],
            **shield,
            **_run_json(self.run),
            "record_version": RECORD_VERSION,
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> EvaluationRecord:
        """Read a record (any version up to :data:`RECORD_VERSION`, and the files written before it had one);
        RecordError names what is missing or wrong."""
        version = data.get("record_version", 1)
        if not isinstance(version, int) or not 1 <= version <= RECORD_VERSION:
            raise RecordError(f"record_version {version!r}: this version reads 1 to {RECORD_VERSION}")
        try:
            shield = data.get("shield")
            return cls(
                success_rate=data["success_rate"],
                success_interval95=_interval(data.get("success_interval95")),
                mean_cost=data["mean_cost"],
                mean_cost_interval95=_interval(data.get("mean_cost_interval95")),
                episodes=int(data["episodes"]),
                mean_mission_time_s=data.get("mean_mission_time_s"),
                roles={role: RoleFigures(**fig) for role, fig in data.get("roles", {}).items()},
                worst_missions=[WorstMission(**w) for w in data.get("worst_missions", [])],
                monitor=None if shield is None else _monitor(shield),
                run=_run(data),
            )
        except KeyError as exc:
            raise RecordError(f"no {exc.args[0]!r} in the evaluation record") from None
        except (TypeError, ValueError) as exc:
            raise RecordError(f"not an evaluation record: {exc}") from None


def _interval_json(interval: Interval | None) -> list[float] | None:
    return None if interval is None else [interval[0], interval[1]]


def _interval(value: Any) -> Interval | None:
    if value is None:
        return None
    low, high = value
    return (low, high)


def _known(figures: RoleFigures) -> dict[str, float]:
    return {k: v for k, v in dataclasses.asdict(figures).items() if v is not None}


def _monitor_json(monitor: RecordedMonitor) -> WorldMonitorJson | SitlMonitorJson:
    if isinstance(monitor, SitlMonitorFigures):
        return {
            "uav_missions": monitor.uav_missions,
            "interventions_per_uav_mission": monitor.interventions_per_uav_mission,
            "max_interventions_per_uav_mission": monitor.max_interventions_per_uav_mission,
            "backup_time_fraction": monitor.backup_time_fraction,
            "unprotected_time_fraction": monitor.unprotected_time_fraction,
            "decisions": monitor.decisions,
            "resets": monitor.resets,
            "max_margin_m": monitor.max_margin_m,
            "uav_missions_with_cost": monitor.uav_missions_with_cost,
            "uavs_left_area": monitor.uavs_left_area,
            "guarantee": monitor.guarantee,
            "scope": monitor.scope,
            "adjusted_time_fraction": monitor.adjusted_time_fraction,
            "held_time_fraction": monitor.held_time_fraction,
            "vehicle_limits": copy.deepcopy(monitor.vehicle_limits),
        }
    out: WorldMonitorJson = {
        "interventions_per_uav_mission": monitor.interventions_per_uav_mission,
        "max_interventions_per_uav_mission": monitor.max_interventions_per_uav_mission,
        "max_switches_per_uav_mission": monitor.max_switches_per_uav_mission,
        "backup_time_fraction": monitor.backup_time_fraction,
        "unprotected_time_fraction": monitor.unprotected_time_fraction,
        "uav_missions_with_cost": monitor.uav_missions_with_cost,
        "uavs_left_area": monitor.uavs_left_area,
        "roles": {
            role: {
                "interventions_per_mission": r.interventions_per_mission,
                "backup_time_fraction": r.backup_time_fraction,
            }
            for role, r in monitor.roles.items()
        },
        "adjusted_time_fraction": monitor.adjusted_time_fraction,
        "held_time_fraction": monitor.held_time_fraction,
    }
    if monitor.config is not None:
        out["config"] = copy.deepcopy(monitor.config)  # as dataclasses.asdict copied it
    return out


def _run_json(run: BatchedRun | SitlRun | None) -> RunJson:
    """What flew, as the record's JSON spreads it (its fields in order; nothing for None)."""
    if run is None:
        return {}
    if isinstance(run, BatchedRun):
        return {"controller": run.controller, "scenario": run.scenario, "seed": run.seed, "cost_limit": run.cost_limit}
    d, w = run.dynamics, run.wind
    return {
        "episodes_requested": run.episodes_requested,
        "pilot": run.pilot,
        "setpoints": run.setpoints,
        "scenario": run.scenario,
        "dynamics": None if d is None else {"model": d.model, "aircraft": d.aircraft},
        "wind": None if w is None else {"speed_m_s": w.speed_m_s, "from_deg": w.from_deg, "turbulence": w.turbulence},
        "seed": run.seed,
        "clock": run.clock,
        "cost_limit": run.cost_limit,
        "signing": run.signing,
    }


def _monitor(data: Mapping[str, Any]) -> RecordedMonitor:
    if "decisions" in data:  # counted by companions
        return SitlMonitorFigures(**data)
    fields = {k: v for k, v in data.items() if k != "roles"}
    roles = {role: RoleMonitorFigures(**fig) for role, fig in data["roles"].items()}
    return WorldMonitorFigures(**fields, roles=roles)


SITL_BEFORE = {"setpoints": "body-rates", "dynamics": None, "wind": None}
"""What a fly file written before these keys flew: body-rate setpoints (the only dialect then), in still air (wind came
with them), on physics it does not state (None)."""


def _run(data: Mapping[str, Any]) -> BatchedRun | SitlRun | None:
    if "pilot" in data and "episodes_requested" in data:  # one fly run; fly.pool's file names the pilot of several
        given = {**SITL_BEFORE, **{f.name: data[f.name] for f in dataclasses.fields(SitlRun) if f.name in data}}
        dynamics, wind = given.pop("dynamics"), given.pop("wind")
        return SitlRun(
            **given,
            dynamics=None if dynamics is None else FlownDynamics(**dynamics),
            wind=None if wind is None else FlownWind(**wind),
        )
    if "controller" in data:
        return BatchedRun(**{f.name: data[f.name] for f in dataclasses.fields(BatchedRun)})
    return None
