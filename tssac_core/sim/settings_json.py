"""Typed settings (a frozen dataclass, such as the configuration ``fly`` gives each process it starts) as one line of
JSON, and back: :func:`to_json` writes every field (None as null, a path as a string, bytes as hexadecimal digits, an
enum by its value, a nested dataclass as an object); :func:`from_json` reads it back equal, checked field by field
with :func:`tssac_core.sim.yaml_file.typed_value`, so a malformed or unknown field is one error line that names it."""

from __future__ import annotations

import argparse
import dataclasses
import enum
import json
from pathlib import Path
from typing import Any, TypeVar

from tssac_core.common.errors import InputError
from tssac_core.sim.scenario import validate
from tssac_core.sim.yaml_file import typed_value
from tssac_core.wire.mission_reset import MissionInput

T = TypeVar("T")


class SettingsError(InputError):
    """Settings that cannot be read; ``str()`` is one line: ``source: field: problem``."""

    def __init__(self, source: str, field_path: str, problem: str) -> None:
        where = f"{source}: {field_path}" if field_path else source
        super().__init__(f"{where}: {problem}")


def plain(value: Any) -> Any:
    """``value`` as JSON data: what :func:`typed_value` reads back as the same value."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, bytes):
        return value.hex()
    if isinstance(value, (tuple, list)):
        return [plain(v) for v in value]
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, float):
        return float(value)  # a numpy float64 (a sampled layout's) as the float it is
    return value


def to_json(settings: Any) -> str:
    """One line of JSON (no newline in it) holding every field of the dataclass ``settings``."""
    return json.dumps(plain(settings), sort_keys=True, allow_nan=False)


def from_json(tp: type[T], text: str, source: str) -> T:
    """The ``tp`` that :func:`to_json` wrote as ``text``; anything else raises :class:`SettingsError` (as does the
    dataclass's own check of its values, a ``ValueError``)."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SettingsError(source, "", f"not JSON ({exc.msg} at line {exc.lineno} column {exc.colno})") from None
    except (RecursionError, ValueError) as exc:  # nested too deep, an integer of thousands of digits
        raise SettingsError(source, "", f"not JSON ({str(exc).split(';')[0] or type(exc).__name__})") from None
    try:
        value: T = typed_value(tp, data, "", source, SettingsError, bounded=False)
    except SettingsError:
        raise
    except ValueError as exc:  # the dataclass refused a value (its __post_init__): UsageError is one
        raise SettingsError(source, "", str(exc)) from None
    return value


STDIN = "-"
"""``--config-json -``: the configuration is standard input's first line."""


def config_text(where: str, missions: MissionInput) -> tuple[str, str]:
    """The text of a child's ``--config-json FILE|-`` and the name to give it in errors: file ``where``'s, or (``-``)
    the first line on ``missions`` (standard input, whose later lines are the served missions). A file that cannot be
    read, or standard input that ends first, is one :class:`SettingsError` line."""
    source = f"--config-json {where}"
    if where != STDIN:
        try:
            return Path(where).read_text(encoding="utf-8"), where
        except OSError as exc:
            raise SettingsError(source, "", f"cannot read it ({exc.strerror or exc})") from None
        except UnicodeDecodeError:
            raise SettingsError(source, "", "not UTF-8 text") from None
    line = missions.line(lambda: False)
    if line is None:
        raise SettingsError(source, "", "standard input ended before the configuration")
    return line, source


def mission_settings_from_json(tp: type[T], text: str, source: str) -> T:
    """:func:`from_json` for a child's configuration that carries a ``scenario``: the scenario validated too (a
    ScenarioError, one line)."""
    settings = from_json(tp, text, source)
    validate(settings.scenario, f"{source}: scenario")  # type: ignore[attr-defined]
    return settings


def add_config_flags(p: argparse.ArgumentParser, help_text: str) -> None:
    """A child's ``--config-json FILE|-`` (its configuration, ``help_text``) and ``--serve``."""
    p.add_argument("--config-json", required=True, metavar="FILE|-", help=help_text)
    p.add_argument(
        "--serve", action="store_true", help="after the mission, read the next ones from standard input (as the CLI's)"
    )
