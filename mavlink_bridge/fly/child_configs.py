"""The typed configurations fly gives the processes it starts, built from its own (:class:`FlyConfig`): the world's
:class:`SitlConfig` and each companion's :class:`CompanionConfig`. fly hands each over as one line of JSON on the
process's standard input (``python -m sim_vehicles.from_config --config-json -``, ``python -m
mavlink_bridge.companion.from_config --config-json -``) rather than as flags for its command line to parse again."""

from __future__ import annotations

from pathlib import Path

from mavlink_bridge.companion.config import LOCKSTEP_GRANT_S, CompanionConfig, default_command_timeout_s
from mavlink_bridge.fly.config import FlyConfig
from tssac_core.deploy.numpy_actor import pilot_file
from tssac_core.sim.scenario import Role, Scenario
from tssac_core.sim.sitl_config import ClockMode, SitlConfig

WORLD_MODULE = "sim_vehicles.from_config"
"""What fly runs for the world (``python -m``, or forked from a crew's fork server)."""
COMPANION_MODULE = "mavlink_bridge.companion.from_config"
"""What fly runs for each companion (``python -m``, or forked from a crew's fork server)."""
LOCKSTEP_SETPOINT_TIMEOUT_S = 5.0
"""Under lockstep the vehicles' setpoint failsafe counts wall seconds at the step barrier: 5 s keeps a
companion that a loaded machine paused for a moment in the loop (failsafes are still counted)."""
LINGER_S = 0.2
"""Simulated seconds the world serves after the mission's end: the end's announcement reaches the companions over a
link with up to this much latency."""


def world_config(
    cfg: FlyConfig, scenario: Scenario, seed: int, truth_log: Path, signing_key: bytes | None
) -> SitlConfig:
    """The world of a mission: ``scenario`` (its layout fixed) with ``seed``'s noise, its vehicles on ports the OS
    gives, in lockstep (a wall-clock setpoint failsafe of :data:`LOCKSTEP_SETPOINT_TIMEOUT_S`) or at real time x
    speedup held at its start until the three companions have the vehicles in GUIDED; every other setting is the
    world's default, as on its command line."""
    lockstep = cfg.lockstep
    serial = cfg.serial_baud is not None
    return SitlConfig(
        scenario=scenario,
        seed=seed,
        base_port=0,
        truth_log=truth_log,
        linger_s=LINGER_S,
        clock=ClockMode.LOCKSTEP if lockstep else ClockMode.REALTIME,
        setpoint_timeout_s=LOCKSTEP_SETPOINT_TIMEOUT_S if lockstep else SitlConfig.setpoint_timeout_s,
        speedup=SitlConfig.speedup if lockstep else cfg.speedup,
        hold_start=not lockstep,
        signing_key=signing_key,
        serial_baud=cfg.serial_baud,
        serial_byte_loss=cfg.serial_byte_loss if serial else SitlConfig.serial_byte_loss,
        monitor_response=cfg.airframe_response,
    )


def tlog_path(cfg: FlyConfig, index: int, role: Role) -> Path | None:
    """``--tlog DIR``: mission ``index``'s tlog of ``role``, DIR/mission-NNN/<role>.tlog; None without."""
    return None if cfg.tlog_dir is None else cfg.tlog_dir / f"mission-{index:03d}" / f"{role.value}.tlog"


def companion_config(
    cfg: FlyConfig,
    role: Role,
    connection: str,
    scenario: Scenario,
    status_json: Path,
    tlog: Path | None,
    signing_key: bytes | None,
) -> CompanionConfig:
    """The companion of ``role`` on ``connection``, flying ``scenario`` (its layout fixed) with fly's pilot, monitor,
    setpoints, clock and telemetry; every other setting is the companion's default, as on its command line."""
    return CompanionConfig(
        connection=connection,
        role=role,
        scenario=scenario,
        model=None if cfg.models is None else pilot_file(cfg.models, role),
        pilot="" if cfg.models is not None else cfg.pilot,
        shield=cfg.shield_tuning.config(cfg.shield_adjust) if cfg.shield else None,
        airframe_response=cfg.airframe_response,
        setpoints=cfg.setpoints,
        lockstep=cfg.lockstep,
        lockstep_grant_s=cfg.lockstep_grant_s if cfg.lockstep else LOCKSTEP_GRANT_S,
        command_timeout_s=default_command_timeout_s(cfg.lockstep),
        lean_telemetry=cfg.lean_telemetry,
        tlog=tlog,
        status_json=status_json,
        signing_key=signing_key,
    )
