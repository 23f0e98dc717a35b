"""Presets: a training recipe in one YAML file, read by ``python -m tssac_core.train --preset FILE`` and by the
experiment grid (its ``train:`` section, and any row ``{preset: FILE}``), so that a recipe exists once.

A preset maps `TrainConfig` fields (the training command's flags: ``steps_per_epoch`` is
``--steps-per-epoch``) to values, and holds the learner settings (``--set``) under ``set:`` (every
algorithm), ``sac_set:`` (the SAC family only) and ``onpolicy_set:`` (ppo, ppo_lag, cpo only)::

    # configs/paper.yaml
    scenario: scenarios/random.yaml
    epochs: 25
    action_repeat: 10
    sac_set: {hidden_sizes: [128, 128], alpha_init: 0.2, beta_lr: 0.001, gamma: 0.995}
    onpolicy_set: {hidden_sizes: [128, 128], gamma: 0.995}

Flags given on the command line win over the preset; ``--set KEY=VALUE`` wins over the preset's value of
KEY. Paths are relative to the directory the command runs in. `read_settings` is the one reader of such a
mapping (a preset file, the grid's ``train:``, a grid row): names, kinds and ranges of the values; a bad one is
one line: ``file: field: problem``. `preset_config` turns presets, layered, into the `TrainConfig` of a run.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Collection, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tssac_core.common.cli import UsageError
from tssac_core.common.options import OptionError, check_field, options
from tssac_core.sim.yaml_file import FileError, read_yaml, typed_value
from tssac_core.train.algorithms import Family, family_of
from tssac_core.train.config import TrainConfig

SET_KEYS = ("set", "sac_set", "onpolicy_set")
NOT_IN_PRESET = ("learner",)
"""TrainConfig fields a preset does not set directly (its learner settings go under SET_KEYS)."""
FIELD_NAMES = tuple(f.name for f in dataclasses.fields(TrainConfig))


class PresetError(UsageError):
    """A preset file that cannot be used; ``str()`` is one line: ``file: field: problem``."""

    def __init__(self, source: str, field_path: str, problem: str) -> None:
        super().__init__(f"{source}: {field_path}: {problem}" if field_path else f"{source}: {problem}")


@dataclass(frozen=True)
class Preset:
    """A preset's content: TrainConfig field values and the learner settings by family."""

    source: str
    values: dict[str, Any] = field(default_factory=dict)
    sets: dict[str, dict[str, Any]] = field(default_factory=dict)

    def learner_settings(self, algo: str) -> dict[str, Any]:
        """The ``--set`` values for ``algo``: ``set``, then its family's (``sac_set`` or ``onpolicy_set``)."""
        family = "onpolicy_set" if family_of(algo) is Family.ON_POLICY else "sac_set"
        return {**self.sets.get("set", {}), **self.sets.get(family, {})}


def preset_config(layers: Sequence[Preset], **fields: Any) -> TrainConfig:
    """The TrainConfig of presets laid one over the other (a later layer's values and learner settings win),
    then ``fields`` (TrainConfig names, as flags on the command line): what ``train --preset FILE`` gives for
    one layer. Each layer's learner settings are those of the algorithm the whole ends with."""
    values: dict[str, Any] = {}
    for layer in layers:
        values.update(layer.values)
    values.update(fields)
    algo = str(values.get("algo", TrainConfig.algo))
    learner: dict[str, Any] = {}
    for layer in layers:
        learner.update(layer.learner_settings(algo))
    return TrainConfig(**{**values, "learner": learner})


def load_preset(path: str | Path) -> Preset:
    """Read and check a preset file (names, value kinds and ranges)."""
    return read_settings(read_yaml(path, PresetError), str(path))


def read_settings(
    data: Any, source: str, where: str = "", error: FileError = PresetError, also: Collection[str] = ()
) -> Preset:
    """A mapping of training settings (a preset file's, or the part of a grid section that is one) as a
    Preset; the first bad key or value raises ``error(source, field path, problem)``. ``where``: the
    mapping's own path in the file (e.g. ``train``); ``also``: the caller's own keys, named among the allowed
    ones when a key is unknown (the caller removed them from ``data``)."""
    if not isinstance(data, dict):
        raise error(source, where, "expected a mapping of training settings")
    allowed = (set(FIELD_NAMES) - set(NOT_IN_PRESET)) | set(SET_KEYS)
    values: dict[str, Any] = {}
    sets: dict[str, dict[str, Any]] = {}
    for key, value in data.items():
        at = f"{where}.{key}" if where else str(key)
        if key not in allowed:
            raise error(source, at, f"unknown key (allowed: {', '.join(sorted(allowed | set(also)))})")
        try:
            if key in SET_KEYS:
                sets[key] = learner_settings(value)
            else:
                values[key] = check_value(key, value)
        except OptionError as exc:
            raise error(source, at, exc.problem) from None
        except ValueError as exc:
            raise error(source, at, str(exc)) from None
    return Preset(source, values, sets)


def learner_settings(value: Any) -> dict[str, Any]:
    """``set``-like: names to numbers, booleans, words, null or lists of numbers (what ``--set`` takes)."""
    if not isinstance(value, dict) or not all(isinstance(k, str) for k in value):
        raise ValueError("expected a mapping of learner settings")
    for key, v in value.items():
        numbers = isinstance(v, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
        if not (isinstance(v, (int, float, bool, str)) or v is None or numbers):
            raise ValueError(f"{key}: expected a number, boolean, word, null or list of numbers, got {v!r}")
    return dict(value)


def check_value(key: str, value: Any) -> Any:
    """One TrainConfig field's value as the training command would take it (OptionError: the problem): its type as
    YAML writes it, then the field's option (tssac_core.common.options)."""
    opt = options(TrainConfig)[key]
    if opt.parse is not None and isinstance(value, str):
        value = opt.parse(value)  # roles as the command writes them, paths as the command writes them
    elif key == "roles" and isinstance(value, list) and all(isinstance(r, str) for r in value):
        value = tuple(value)
    elif key == "roles":
        raise OptionError(key, f"expected a list of roles, got {value!r}")
    default = getattr(TrainConfig, key, None)
    if not opt.choices and isinstance(default, (bool, int, float, str)):
        value = typed_value(type(default), value, key, "", _problem)  # the scenario's and the grid's checks
    return check_field(TrainConfig, key, value)


def _problem(source: str, field: str, problem: str) -> OptionError:
    """:func:`typed_value`'s error as :func:`check_value`'s."""
    del source
    return OptionError(field, problem)
