"""A mission's outcome (from the world's truth log, or from the companions) and the results JSON."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from mavlink_bridge.fly.config import FlyConfig, monitor_scope
from mavlink_bridge.fly.mission_log import MissionRecord
from mavlink_bridge.fly.mission_row import CompanionStatus, MissionRow, Outcome, ShieldCounts
from tssac_core.common.evaluation_record import (
    EvaluationRecord,
    EvaluationRecordJson,
    FlownDynamics,
    FlownWind,
    RoleFigures,
    SitlMonitorFigures,
    SitlRun,
    WorstMission,
)
from tssac_core.common.stats import (
    bootstrap_mean_interval,
    cvar,
    wilson_interval,
    worst_missions,
)
from tssac_core.sim.scenario import ROLES, Dynamics

WORST_MISSIONS = 10
"""How many of the costliest UAV-missions the JSON lists (as tssac_core.evaluate's)."""


def outcome(record: MissionRecord, cost_limit: float) -> Outcome:
    tasks = record.task_done()
    return {
        "success": record.success,
        "end": record.end,
        "steps": record.steps,
        "sim_time_s": round(record.sim_time_s, 3),
        "cost": record.cost,
        "within_cost_limit": {k: v <= cost_limit for k, v in record.cost.items()},
        "task_done": tasks,
        "failsafe_steps": record.failsafe_steps,
        "left_area": record.event_count("FENCE"),
        "world_flight_cpu_s": record.summary.get("flight_cpu_s") if record.summary is not None else None,
    }


def outcome_from_companions(statuses: dict[str, CompanionStatus]) -> Outcome:
    ends = [s.get("status") for s in statuses.values()]
    success = "success" in ends
    end = "success" if success else next((e for e in ends if e in ("geofence", "episode_cap")), "unknown")
    times = [t for s in statuses.values() if (t := s.get("vehicle_time_s")) is not None]
    return {"success": success, "end": end, "sim_time_s": max(times) if times else None, "cost": None}


def costed_rows(rows: list[MissionRow]) -> list[tuple[MissionRow, dict[str, float]]]:
    """The rows whose cost is known, each with its cost per role."""
    return [(r, cost) for r in rows if (cost := r.get("cost"))]


def monitor_figures(rows: list[MissionRow], scope: str | None) -> SitlMonitorFigures:
    """The monitor's figures over the missions, from the companions' counts: interventions per UAV-mission, the
    fraction of control steps under the backup, the largest margin used; and what the guarantee is about (UAV-missions
    with any cost, UAVs that left the area). ``scope``: why the guarantee does not hold here (None: it does)."""
    shielded = [(s, shield) for r in rows for s in r.get("companions", {}).values() if (shield := s.get("shield"))]
    counts: list[ShieldCounts] = [shield for _, shield in shielded]
    control = sum(s.get("control_steps") or 0 for s, _ in shielded)
    costed = costed_rows(rows)
    return SitlMonitorFigures(
        uav_missions=len(counts),
        interventions_per_uav_mission=float(np.mean([c["interventions"] for c in counts])) if counts else None,
        max_interventions_per_uav_mission=max((c["interventions"] for c in counts), default=None),
        backup_time_fraction=sum(c["backup_steps"] for c in counts) / max(1, control) if counts else None,
        adjusted_time_fraction=sum(c.get("adjusted_steps", 0) for c in counts) / max(1, control) if counts else None,
        held_time_fraction=sum(c.get("held_steps", 0) for c in counts) / max(1, control) if counts else None,
        vehicle_limits=vehicle_limits(rows) if counts else None,
        unprotected_time_fraction=sum(c["unprotected_steps"] for c in counts) / max(1, control) if counts else None,
        decisions=sum(c["decisions"] for c in counts),
        resets=sum(c["resets"] for c in counts),
        max_margin_m=max((c["max_margin_m"] for c in counts), default=None),
        uav_missions_with_cost=int(sum(v > 0 for _, cost in costed for v in cost.values())) if costed else None,
        uavs_left_area=int(sum(sum(r.get("left_area", {}).values()) for r, _ in costed)) if costed else None,
        guarantee=scope is None,
        scope=scope,
    )


def vehicle_limits(rows: list[MissionRow]) -> dict[str, dict[str, object] | None]:
    """Per role, the achievable limits its vehicle published to the first companion that read them (None: none did)."""
    seen: dict[str, dict[str, object] | None] = {}
    for r in rows:
        for role, status in r.get("companions", {}).items():
            said = status.get("vehicle_limits")
            if seen.get(role) is None and status.get("shield"):
                seen[role] = said if isinstance(said, dict) else None
    return seen


def role_figures(
    rows: list[MissionRow], costed: list[tuple[MissionRow, dict[str, float]]], name: str, cost_limit: float
) -> RoleFigures:
    """One role's figures: its cost tail and task success over the missions whose cost is known (``costed``), its
    companions' control latency over all."""
    tail = RoleFigures()
    if costed:
        costs = np.array([cost[name] for _, cost in costed])
        tail = RoleFigures(
            mean_cost=float(costs.mean()),
            max_cost=float(costs.max()),
            within_cost_limit=float((costs <= cost_limit).mean()),
            cvar95_cost=cvar(costs),
            task_success_rate=float(np.mean([bool(r.get("task_done", {}).get(name)) for r, _ in costed])),
        )
    companions = [r["companions"][name] for r in rows if name in r.get("companions", {})]
    p50 = [p for c in companions if (p := c.get("latency_p50_ms")) is not None]
    p99 = [p for c in companions if (p := c.get("latency_p99_ms")) is not None]
    if not p50:
        return tail
    return dataclasses.replace(tail, latency_p50_ms=float(np.median(p50)), latency_p99_ms=float(np.max(p99)))


def flown_run(cfg: FlyConfig) -> SitlRun:
    """What flew the campaign, where, on which clock."""
    dynamics = cfg.scenario.dynamics or Dynamics()
    wind = cfg.scenario.wind
    if cfg.connect is not None:
        clock = "connected, lockstep" if cfg.lockstep else "connected"
    else:
        clock = "lockstep" if cfg.lockstep else f"speedup {cfg.speedup:g}"
    return SitlRun(
        episodes_requested=cfg.episodes,
        pilot=str(cfg.models) if cfg.models is not None else cfg.pilot,
        setpoints=cfg.setpoints.value,
        scenario=str(cfg.scenario_path),
        # The vehicles of --connect fly whatever physics they fly: unknown here.
        dynamics=None if cfg.connect is not None else FlownDynamics(dynamics.model.value, dynamics.aircraft),
        wind=None if wind is None else FlownWind(wind.speed_m_s, wind.from_deg, wind.turbulence.value),
        seed=cfg.seed,
        clock=clock,
        cost_limit=cfg.scenario.cost_limit,
        signing=cfg.signing_key_path is not None,
    )


def summarise(rows: list[MissionRow], cfg: FlyConfig) -> EvaluationRecord:
    """The campaign's record: success_rate and mean_cost with their 95% intervals, episodes, per-role figures with the
    tail (within C, worst, CVaR_0.95), the costliest UAV-missions, as ``tssac_core.evaluate``'s
    (tssac_core.common.stats), with the cost figures None when the cost is unknown."""
    n = len(rows)
    wins = int(sum(bool(r.get("success")) for r in rows))
    times = [t for r in rows if (t := r.get("sim_time_s")) is not None]
    costed = costed_rows(rows)
    mean_cost: float | None = None
    cost_interval: tuple[float, float] | None = None
    worst: list[WorstMission] = []
    if costed:
        cost = np.array([[c[role.value] for role in ROLES] for _, c in costed], dtype=np.float64)
        interval = bootstrap_mean_interval(cost)
        mean_cost, cost_interval = float(cost.mean()), (interval.low, interval.high)
        worst = [
            dataclasses.replace(w, mission=costed[w.mission][0]["index"])
            for w in worst_missions(
                cost, [r["seed"] for r, _ in costed], [role.value for role in ROLES], WORST_MISSIONS
            )
        ]
    rate = wilson_interval(wins, n) if n else None
    return EvaluationRecord(
        success_rate=wins / n if n else None,
        success_interval95=(rate.low, rate.high) if rate is not None else None,
        mean_cost=mean_cost,
        mean_cost_interval95=cost_interval,
        episodes=n,
        mean_mission_time_s=float(np.mean(times)) if times else None,
        roles={role.value: role_figures(rows, costed, role.value, cfg.scenario.cost_limit) for role in ROLES},
        worst_missions=worst,
        monitor=monitor_figures(rows, monitor_scope(cfg.scenario, cfg.airframe_response)) if cfg.shield else None,
        run=flown_run(cfg),
    )


class CampaignJson(EvaluationRecordJson):
    """What ``fly --json`` writes: the record, the missions' rows and how the campaign ended."""

    missions: list[MissionRow]
    interrupted: bool
    error: str | None
    wall_time_s: float
    resume_key: str


@dataclass(frozen=True)
class CampaignResults:
    """fly's results: the record, each mission's row (in mission order), and how the campaign ended."""

    record: EvaluationRecord
    missions: list[MissionRow]
    interrupted: bool
    error: str | None
    wall_time_s: float
    resume_key: str = ""
    """What ``--resume`` checks a file against (:func:`mavlink_bridge.fly.resume.campaign_key`)."""

    def to_json(self) -> CampaignJson:
        return {
            **self.record.to_json(),
            "missions": self.missions,
            "interrupted": self.interrupted,
            "error": self.error,
            "wall_time_s": round(self.wall_time_s, 3),
            "resume_key": self.resume_key,
        }


def campaign_results(
    rows: list[MissionRow], cfg: FlyConfig, interrupted: bool, error: str | None, wall_s: float, key: str
) -> CampaignResults:
    """The results of the missions flown (in mission order: missions flown side by side end in any order), with how
    the campaign ended."""
    rows.sort(key=lambda r: r["index"])
    return CampaignResults(summarise(rows, cfg), rows, interrupted, error, wall_s, key)
