"""Presets: a training recipe in one YAML file, read by ``python -m tssac_core.train --preset FILE`` and by the
experiment grid (``train: {preset: FILE}``), so that a recipe exists once.

A preset maps the training command's flags, by their `TrainConfig` names (``steps_per_epoch`` is
``--steps-per-epoch``), to values, and holds the learner settings (``--set``) under ``set:`` (every
algorithm), ``sac_set:`` (the SAC family only) and ``onpolicy_set:`` (ppo, ppo_lag, cpo only)::

    # configs/paper.yaml
    scenario: scenarios/random.yaml
    epochs: 25
    action_repeat: 10
    sac_set: {hidden_sizes: [128, 128], alpha_init: 0.2, beta_lr: 0.001, gamma: 0.995}
    onpolicy_set: {hidden_sizes: [128, 128], gamma: 0.995}

Flags given on the command line win over the preset; ``--set KEY=VALUE`` wins over the preset's value of
KEY. Paths are relative to the directory the command runs in. A bad file is one line: ``file: field: problem``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tssac_core.cli import UsageError
from tssac_core.sim.yaml_file import read_yaml
from tssac_core.train.algorithms import Family, family_of
from tssac_core.train.config import TrainConfig

SET_KEYS = ("set", "sac_set", "onpolicy_set")
NOT_IN_PRESET = ("learner",)
PATH_FIELDS = ("scenario", "init_from", "teammates")
"""TrainConfig fields a preset does not set directly (its learner settings go under SET_KEYS)."""


class PresetError(UsageError):
    """A preset file that cannot be used; ``str()`` is one line: ``file: field: problem``."""

    def __init__(self, source: str, field_path: str, problem: str) -> None:
        super().__init__(f"{source}: {field_path}: {problem}" if field_path else f"{source}: {problem}")


@dataclass(frozen=True)
class Preset:
    """A preset file's content: TrainConfig field values and the learner settings by family."""

    source: str
    values: dict[str, Any] = field(default_factory=dict)
    sets: dict[str, dict[str, Any]] = field(default_factory=dict)

    def argparse_defaults(self) -> dict[str, Any]:
        """The values as the training command's parser holds them (roles comma-separated, paths as Path)."""
        out: dict[str, Any] = {}
        for key, value in self.values.items():
            if key == "roles":
                value = ",".join(value)
            elif key in PATH_FIELDS:
                value = Path(value)
            out[key] = value
        return out

    def learner_settings(self, algo: str) -> dict[str, Any]:
        """The ``--set`` values for ``algo``: ``set``, then its family's (``sac_set`` or ``onpolicy_set``)."""
        family = "onpolicy_set" if family_of(algo) is Family.ON_POLICY else "sac_set"
        return {**self.sets.get("set", {}), **self.sets.get(family, {})}


FIELD_TYPES = {f.name: f.type for f in dataclasses.fields(TrainConfig)}


def load_preset(path: str | Path) -> Preset:
    """Read and check a preset file (names and value kinds; the values' ranges are checked by the command)."""
    source = str(path)
    data = read_yaml(path, PresetError)
    if not isinstance(data, dict):
        raise PresetError(source, "", "expected a mapping of training settings")
    allowed = (set(FIELD_TYPES) - set(NOT_IN_PRESET)) | set(SET_KEYS)
    values: dict[str, Any] = {}
    sets: dict[str, dict[str, Any]] = {}
    for key, value in data.items():
        if key not in allowed:
            raise PresetError(source, str(key), f"unknown key (allowed: {', '.join(sorted(allowed))})")
        if key in SET_KEYS:
            if not isinstance(value, dict) or not all(isinstance(k, str) for k in value):
                raise PresetError(source, key, "expected a mapping of learner settings")
            sets[key] = dict(value)
            continue
        values[key] = check_value(source, key, value)
    return Preset(source, values, sets)


def check_value(source: str, key: str, value: Any) -> Any:
    default = getattr(TrainConfig, key, None)
    if key == "roles":
        if isinstance(value, str):
            value = [r.strip() for r in value.split(",") if r.strip()]
        if not isinstance(value, list) or not all(isinstance(r, str) for r in value):
            raise PresetError(source, key, f"expected a list of roles, got {value!r}")
        return tuple(value)
    if isinstance(default, bool) or isinstance(value, bool):
        raise PresetError(source, key, f"expected a {type(default).__name__}, got {value!r}")
    if isinstance(default, int) and not isinstance(value, int):
        raise PresetError(source, key, f"expected an integer, got {value!r}")
    if isinstance(default, float) and not isinstance(value, (int, float)):
        raise PresetError(source, key, f"expected a number, got {value!r}")
    if isinstance(default, str) and not isinstance(value, str):
        raise PresetError(source, key, f"expected a word or path, got {value!r}")
    return float(value) if isinstance(default, float) else value
