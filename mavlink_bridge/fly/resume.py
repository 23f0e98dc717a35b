"""``fly --resume --json FILE``: a campaign that stopped part-way (interrupted, a session's end, an error) flies on
from its results file, only the missions it has not flown; a finished campaign asked for more ``--episodes`` adds
them. Every mission is one layout of its own seed (seed + index), so the merged file is the campaign one run would
have flown.

The file names what flew it: ``resume_key``, a digest of every setting that decides what a mission does (the
scenario, the pilot and its files, the seed, the clock, the monitor and the airframe response it predicts with, the
command dialect, the link). A file of other settings, or one that is not fly's, is refused in one line before anything
flies, and left as it is; a file that does not exist yet is a campaign from its start. A mission row that did not end
(a timeout, a crash: no cost) is flown again.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path
from typing import Any

from mavlink_bridge.fly.config import FlyConfig
from mavlink_bridge.fly.mission_row import MissionRow
from mavlink_bridge.fly.pool import PoolError, check_campaign, read_results
from tssac_core.common.errors import InputError
from tssac_core.common.files import sha256_file
from tssac_core.deploy.numpy_actor import pilot_file
from tssac_core.sim.scenario import ROLES
from tssac_core.sim.shield_tuning import ShieldTuning


class ResumeError(InputError):
    """A results file the campaign cannot resume from; ``str()`` is one line."""


def _pilot_files(models: Path | None) -> dict[str, str] | None:
    """The digests of the files the team's pilots load, by role (None: no models, a built-in pilot); the directory's
    other files (evaluations written beside them) do not decide a mission."""
    if models is None:
        return None
    return {role.value: sha256_file(pilot_file(models, role)) for role in ROLES}


def campaign_key(cfg: FlyConfig) -> str:
    """The digest of every setting that decides what the campaign's missions do (module docstring)."""
    settings: dict[str, Any] = {
        "scenario": dataclasses.asdict(cfg.scenario),
        "models": _pilot_files(cfg.models),
        "pilot": cfg.pilot if cfg.models is None else None,
        "seed": cfg.seed,
        "clock": "lockstep" if cfg.lockstep else cfg.speedup,
        "lockstep_grant_s": cfg.lockstep_grant_s,
        "shield": cfg.shield,
        "shield_adjust": cfg.shield_adjust,
        **({"shield_tuning": dataclasses.asdict(cfg.shield_tuning)} if cfg.shield_tuning != ShieldTuning() else {}),
        "airframe_response": None if cfg.airframe_response is None else sha256_file(cfg.airframe_response),
        "setpoints": cfg.setpoints.value,
        "lean_telemetry": cfg.lean_telemetry,
        "serial": [cfg.serial_baud, cfg.serial_byte_loss],
        "connect": cfg.connect,
        "signing": cfg.signing_key_path is not None,
    }
    text = json.dumps(settings, sort_keys=True, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _ended(row: Any) -> bool:
    """A mission row whose mission ended with its cost known (others are flown again)."""
    return isinstance(row, dict) and isinstance(row.get("cost"), dict) and row.get("end") != "timeout"


def resumed_rows(cfg: FlyConfig, key: str) -> list[MissionRow]:
    """The missions ``cfg.json_path`` already holds for this campaign (none: the file does not exist yet); ResumeError
    (one line) for a file that is not fly's, of other settings, or holding missions beyond ``--episodes``."""
    path = cfg.json_path
    if path is None:
        raise ResumeError("--resume needs --json FILE: the campaign's results file to fly on from")
    if not path.exists():
        return []
    try:
        raw = read_results(path)
    except PoolError as exc:
        raise ResumeError(f"--resume: {exc}") from None
    if raw.get("resume_key") != key:
        raise ResumeError(
            f"--resume: {path} was flown with other settings than this command's (or by a fly without a resume key): "
            "give another --json, or remove the file to fly from the start"
        )
    rows: list[MissionRow] = [row for row in raw["missions"] if _ended(row)]
    if rows:
        try:
            check_campaign({**raw, "missions": rows, "episodes": len(rows)}, str(path))
        except PoolError as exc:
            raise ResumeError(f"--resume: {exc}") from None
    beyond = [row["index"] for row in rows if row["index"] >= cfg.episodes]
    if beyond:
        raise ResumeError(
            f"--resume: {path} holds missions up to index {max(beyond)}: --episodes must be at least {max(beyond) + 1}"
        )
    return rows
