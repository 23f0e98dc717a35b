"""What runs written by older versions of TSSAC mean, in one place.

- ``config.json``: settings that did not exist when a run was written take the value the run used
  (`OLDER_RUN_SETTINGS`, and the multiplier signal of the SAC family: `config_from_saved`); the learner
  settings, ``learner`` now, were ``sac`` (`RENAMED_SETTINGS`).
- Resume states written before the one format (one per learner family): :func:`tssac_core.train.resume.from_legacy`.
- Pickles: role checkpoints (``<role>.pt``) and resume states (``resume/<role>.pt``) hold plain dicts,
  tensors, numpy arrays and builtins; they name no module of ``tssac_core`` (tests/test_legacy.py checks the
  shipped models and this version's own files), so the package's layout can change without breaking them.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

from tssac_core.common.cli import UsageError
from tssac_core.common.options import OptionError
from tssac_core.train.algorithms import ALGORITHMS
from tssac_core.train.config import TrainConfig, has_multiplier_signal

OLDER_RUN_SETTINGS = {"cost_margin_km": 0.0, "selection": "within_limit"}
"""Settings that a config.json written before they existed means (those runs trained on eq. 11 exactly, and
every algorithm shipped the best epoch within the cost limit)."""


RENAMED_SETTINGS = {"sac": "learner"}
"""config.json keys of older runs -> their TrainConfig field now."""


def config_from_saved(saved: Any, source: str | Path = "config.json") -> TrainConfig:
    """The TrainConfig of a run's config.json; keys it lacks take their value from before they existed.

    A file that is not a training configuration of this TSSAC (not a mapping, settings it does not know,
    no roles) raises UsageError naming ``source``.
    """
    if not isinstance(saved, dict):
        raise UsageError(f"{source}: not a training configuration")
    saved = {RENAMED_SETTINGS.get(key, key): value for key, value in saved.items()}
    unknown = sorted(set(saved) - {f.name for f in dataclasses.fields(TrainConfig)})
    if unknown:
        raise UsageError(f"{source}: settings this TSSAC does not know: {', '.join(unknown)}")
    full = {**OLDER_RUN_SETTINGS, **saved}
    if not isinstance(full.get("roles"), list):
        raise UsageError(f"{source}: roles: expected a list of role names")
    if full.get("algo") not in ALGORITHMS:
        raise UsageError(f"{source}: algo: expected one of {', '.join(ALGORITHMS)}, got {full.get('algo')!r}")
    learner = full.get("learner")
    if has_multiplier_signal(full["algo"]) and isinstance(learner, dict) and "multiplier_signal" not in learner:
        full["learner"] = {**learner, "multiplier_signal": "q_c"}  # what their multiplier measured before the setting
    try:
        return TrainConfig(**{**full, "roles": tuple(full["roles"])})
    except OptionError as exc:  # the options' checks, as the command line and presets make them
        raise UsageError(f"{source}: {exc.field}: {exc.problem}") from None


def read_config(path: Path, what: str) -> TrainConfig:
    """The TrainConfig in the JSON file ``path`` (a run's config.json, or a grid job's); UsageError, one line
    starting with ``what`` (the flag that named it), if it cannot be read."""
    try:
        saved = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise UsageError(f"{what}: {path} is not readable ({exc})") from None
    return config_from_saved(saved, path)
