"""The typed configuration fly gives each companion it starts: a :class:`CompanionConfig` built from fly's own
(:class:`FlyConfig`), handed over as one line of JSON (``python -m mavlink_bridge.companion.from_config
--config-json -``) rather than as flags for the companion's command line to parse again."""

from __future__ import annotations

from pathlib import Path

from mavlink_bridge.companion.config import LOCKSTEP_GRANT_S, CompanionConfig, default_command_timeout_s
from mavlink_bridge.fly.config import FlyConfig
from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.deploy.numpy_actor import pilot_file
from tssac_core.sim.scenario import Role, Scenario

COMPANION_MODULE = "mavlink_bridge.companion.from_config"
"""What fly runs for each companion (``python -m``, or forked from a crew's fork server)."""


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
        shield=ShieldConfig() if cfg.shield else None,
        setpoints=cfg.setpoints,
        lockstep=cfg.lockstep,
        lockstep_grant_s=cfg.lockstep_grant_s if cfg.lockstep else LOCKSTEP_GRANT_S,
        command_timeout_s=default_command_timeout_s(cfg.lockstep),
        lean_telemetry=cfg.lean_telemetry,
        tlog=tlog,
        status_json=status_json,
        signing_key=signing_key,
    )
