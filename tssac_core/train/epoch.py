"""What every training loop shares: the earlier roles as teammates, the role's worlds, one epoch's
figures, the stop rule, and shipping the role."""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tssac_core.algos.sac_lagrangian import UpdateStats
from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.common.errors import CheckpointError
from tssac_core.deploy.export import export_actor
from tssac_core.deploy.manifest import record
from tssac_core.deploy.policy import Policy, read_checkpoint
from tssac_core.sim.airframe_response import load_response
from tssac_core.sim.env import RoleTask, TaskStep
from tssac_core.sim.hard_layouts import HardLayouts
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.pilots import PilotSpec
from tssac_core.sim.role_task import MonitorInTraining
from tssac_core.sim.scenario import ROLES, Role, Scenario
from tssac_core.sim.varied_airframes import AirframeVariation
from tssac_core.train.config import TrainConfig, TrainMonitor, reward_config
from tssac_core.train.rundir import MetricsRow, role_checkpoint
from tssac_core.train.validation import EpochSelector

logger = logging.getLogger("tssac_core.train")


def teammates_for(role: Role, cfg: TrainConfig, out: Path) -> dict[str, PilotSpec]:
    """Earlier roles fly their trained policies (the judgement condition); later ones are parked."""
    pilots: dict[str, PilotSpec] = {}
    for earlier in ROLES[: role.index]:
        pilots[earlier.value] = Policy.load(role_checkpoint(cfg, out, earlier), earlier)
    return pilots


def make_task(
    cfg: TrainConfig, scenario: Scenario, role: Role, mode: ObservationMode, teammates: dict[str, PilotSpec]
) -> RoleTask:
    """The training worlds of one role: its reward, its (tightened) cost, its teammates, its seed."""
    variation = airframe_variation(cfg)
    return RoleTask(
        scenario,
        role,
        cfg.envs,
        mode,
        teammates=teammates,
        seed=cfg.seed * 1000 + role.index,
        reward_config=reward_config(cfg),
        cost_margin_m=cfg.cost_margin_km * 1000.0,
        hard_layouts=HardLayouts(cfg.hard_layouts, cfg.hard_detour_km),
        airframes=variation,
        monitor=monitor_in_training(cfg, scenario, variation),
    )


def airframe_variation(cfg: TrainConfig) -> AirframeVariation | None:
    """The varied airframes the run trains on (TrainConfig.airframe_response), or None: eq. 5-6 exactly."""
    if not cfg.airframe_response:
        return None
    response = load_response(cfg.airframe_response)
    return AirframeVariation.from_response(
        response, cfg.vary_wind_m_s, cfg.vary_turn_noise_deg_s, cfg.vary_nominal_fraction
    )


def monitor_in_training(
    cfg: TrainConfig, scenario: Scenario, variation: AirframeVariation | None
) -> MonitorInTraining | None:
    """The monitor the training worlds fly through (TrainConfig.train_monitor), or None. In wind (the run's varied
    airframes, ``variation``) its backups end in the ground loiter, bounded on the lag model at the corners of their
    spans."""
    if cfg.train_monitor is TrainMonitor.OFF:
        return None
    shield = ShieldConfig(margin_m=cfg.train_monitor_margin_m, adjust=True)
    loiter = None
    if variation is not None and variation.wind_m_s[1] > 0:
        loiter = variation.envelope_loiter_bound(load_response(cfg.airframe_response).loiter_law(), scenario)
    return MonitorInTraining(shield, cfg.action_repeat, loiter, costs_overrule=cfg.train_monitor is TrainMonitor.ON)


def reached_stop(cfg: TrainConfig, row: MetricsRow) -> bool:
    """The epoch's training task success reached ``cfg.stop_at_task_success`` (never when that is 0)."""
    return cfg.stop_at_task_success > 0 and row.figures["task_success"] >= cfg.stop_at_task_success


@dataclass
class EpochLog:
    """Accumulates one epoch's figures."""

    returns: list[float] = field(default_factory=list)
    costs: list[float] = field(default_factory=list)
    hazard_costs: list[float] = field(default_factory=list)
    tasks: list[float] = field(default_factory=list)
    successes: list[float] = field(default_factory=list)
    stats: list[UpdateStats] = field(default_factory=list)
    env_time: float = 0.0
    update_time: float = 0.0

    def record_episodes(self, step: TaskStep, ended: np.ndarray) -> None:
        """Add the figures of the episodes that ended at this step (``ended``, (N,) bool)."""
        self.returns += step.episode_return[ended].tolist()
        self.costs += step.episode_cost[ended].tolist()
        self.hazard_costs += step.episode_hazard_cost[ended].tolist()
        self.tasks += step.episode_task[ended].astype(float).tolist()
        self.successes += step.episode_success[ended].astype(float).tolist()

    def row(self, role: Role, epoch: int, env_steps: int, updates: int, steps: int) -> MetricsRow:
        def mean(xs: list[float]) -> float:
            return float(np.mean(xs)) if xs else math.nan

        row: dict[str, float] = {
            "epoch": epoch,
            "env_steps": env_steps,
            "episodes": len(self.returns),
            "return": mean(self.returns),
            "cost": mean(self.costs),
            "hazard_cost": mean(self.hazard_costs),
            "task_success": mean(self.tasks),
            "mission_success": mean(self.successes),
        }
        for f in dataclasses.fields(UpdateStats):
            row[f.name] = mean([getattr(s, f.name) for s in self.stats])
        row["env_steps_per_s"] = steps / self.env_time if self.env_time > 0 else math.nan
        row["updates_per_s"] = len(self.stats) / self.update_time if self.update_time > 0 else math.nan
        row["updates"] = updates
        return MetricsRow(role, row)


def log_stop(role: Role, epoch: int, row: MetricsRow) -> None:
    logger.info(
        "%s: task success %.2f in epoch %d (%d decisions) reaches --stop-at-task-success: role done",
        role.value,
        row.figures["task_success"],
        epoch,
        row.figures["env_steps"],
    )


def ship_role(out: Path, role: Role, selector: EpochSelector, write_checkpoint: Callable[[Path], None]) -> None:
    """Write ``<role>.pt``: the best validated epoch's checkpoint (without validation, the last epoch's),
    and its actor as ``<role>.npz`` (tssac_core.deploy.numpy_actor), then record both in the run's ``SHA256SUMS``
    (tssac_core.deploy.manifest)."""
    final = out / f"{role.value}.pt"
    try:
        best = selector.finish(final, write_checkpoint)
    except CheckpointError as exc:  # the best epoch's file was damaged: never ship it
        logger.warning("%s; shipping the last epoch instead", exc)
        write_checkpoint(final)
        best = None
    read_checkpoint(final)  # what ships loads (CheckpointError otherwise: one line, and the role is not finished)
    npz = export_actor(final)  # <role>.npz: what the companion flies, without torch
    record(out, [final.name, npz.name])  # last: until the manifest lists them, a resume ships the role again
    if best is not None:
        logger.info(
            "%s: shipping epoch %d (validation: mission success %.2f, cost %.2f)",
            role.value,
            best.epoch,
            best.mission_success,
            best.mean_cost,
        )
