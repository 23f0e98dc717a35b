"""Reading a YAML file for a command (:func:`read_yaml`) and its values as typed settings (:func:`typed_value`): any
problem becomes one error line naming the file and the field."""

from __future__ import annotations

import codecs
import dataclasses
import enum
import math
import types
import typing
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import yaml

FileError = Callable[[str, str, str], Exception]
"""Builds the caller's error from (file, field path, problem)."""

MAX_MAGNITUDE = 1e9
"""No number in a scenario, preset or grid file is larger than this (in size): what the files' own checks do not
bound, this does."""
MAX_YAML_BYTES = 1 << 20
"""The largest file read (1 MiB): scenarios, presets and grids are a few kB; a huge file is refused before
PyYAML spends minutes on it."""
_BOMS = (
    (codecs.BOM_UTF32_LE, "utf-32"),
    (codecs.BOM_UTF32_BE, "utf-32"),
    (codecs.BOM_UTF8, "utf-8-sig"),
    (codecs.BOM_UTF16_LE, "utf-16"),
    (codecs.BOM_UTF16_BE, "utf-16"),
)
"""YAML's encodings (UTF-8, UTF-16, UTF-32), told apart by the byte order mark; without one, UTF-8. UTF-32 LE
comes before UTF-16 LE: its mark starts with UTF-16 LE's."""


def read_yaml(path: str | Path, error: FileError) -> Any:
    """The parsed content of ``path``; an unreadable, too large or undecodable file or invalid YAML raises
    ``error(file, "", problem)``."""
    source = str(path)
    text = _read_text(Path(path), source, error)
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" at line {mark.line + 1}" if mark is not None else ""
        raise error(source, "", f"not valid YAML{at}: {getattr(exc, 'problem', exc)}") from None
    except (ValueError, OverflowError, RecursionError) as exc:
        # e.g. an integer of more than 4,300 digits (Python's int-from-string limit), or nesting too deep
        reason = str(exc).split(";")[0] or type(exc).__name__
        raise error(source, "", f"a value cannot be read: {reason}") from None


def _read_text(path: Path, source: str, error: FileError) -> str:
    """At most :data:`MAX_YAML_BYTES` of ``path``, decoded as its byte order mark says (UTF-8 without one)."""
    try:
        with path.open("rb") as fh:
            data = fh.read(MAX_YAML_BYTES + 1)
    except OSError as exc:
        raise error(source, "", f"cannot read file ({exc.strerror or exc})") from None
    if len(data) > MAX_YAML_BYTES:
        raise error(source, "", f"file larger than {MAX_YAML_BYTES // 1024} KiB: not a scenario, preset or grid")
    encoding = next((name for bom, name in _BOMS if data.startswith(bom)), "utf-8")
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        raise error(
            source, "", f"not {encoding.upper().removesuffix('-SIG')} text (byte {exc.start}); save it as UTF-8"
        ) from None


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", str(tp))


def typed_value(tp: Any, value: Any, where: str, source: str, error: FileError, bounded: bool = True) -> Any:
    """``value`` (plain YAML or JSON data) as type ``tp`` (a dataclass, an enum by its values, tuple, dict, optional,
    float, int, bool, str, a path or bytes), checked all the way down; the first problem raises ``error(source, field
    path, problem)``. Scenario files, preset files, grid files and the configurations fly gives its processes
    (:mod:`tssac_core.sim.settings_json`) are read with it, so a value is judged, and its problem worded, the same in
    each. ``bounded``: integers beyond :data:`MAX_MAGNITUDE` are refused (a file a user writes); False for a program's
    own settings, whose dataclass checks its values (a seed goes up to 2**63 - 1)."""
    at = _Place(where, source, error, bounded)
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        return _optional(tp, value, at)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return _enum_member(tp, value, at)
    if dataclasses.is_dataclass(tp):
        return _dataclass(cast(type, tp), value, at)
    if origin is tuple:
        return _tuple(typing.get_args(tp), value, at)
    if origin is dict:
        return _mapping(typing.get_args(tp)[1], value, at)
    scalar = _SCALARS.get(tp)
    if scalar is None:
        raise TypeError(f"unsupported schema type {_type_name(tp)} at {where}")  # a bug in the schema
    return scalar(value, at)


@dataclass(frozen=True)
class _Place:
    """Where a value is: its field path in its file, and the error that names them."""

    where: str
    source: str
    error: FileError
    bounded: bool = True
    """Integers beyond :data:`MAX_MAGNITUDE` are refused."""

    def fail(self, problem: str) -> Exception:
        return self.error(self.source, self.where, problem)

    def into(self, name: str) -> _Place:
        return _Place(_join(self.where, name), self.source, self.error, self.bounded)

    def item(self, index: int) -> _Place:
        return _Place(f"{self.where}[{index}]", self.source, self.error, self.bounded)

    def read(self, tp: Any, value: Any) -> Any:
        return typed_value(tp, value, self.where, self.source, self.error, self.bounded)


def _optional(tp: Any, value: Any, at: _Place) -> Any:
    args = typing.get_args(tp)
    if value is None and type(None) in args:
        return None
    (inner,) = [a for a in args if a is not type(None)]
    return at.read(inner, value)


def _enum_member(tp: type[enum.Enum], value: Any, at: _Place) -> enum.Enum:
    allowed = [str(member.value) for member in tp]
    if not isinstance(value, str) or value not in allowed:
        raise at.fail(f"expected one of {', '.join(allowed)}, got {_short(value)}")
    return tp(value)


def _dataclass(tp: type, value: Any, at: _Place) -> Any:
    if not isinstance(value, dict):
        raise at.fail(f"expected a mapping, got {type(value).__name__}")
    hints = typing.get_type_hints(tp)
    names = {f.name for f in dataclasses.fields(tp)}
    for key in value:
        if key not in names:
            raise at.into(str(key)).fail(f"unknown key (allowed: {', '.join(sorted(names))})")
    kwargs = {}
    for f in dataclasses.fields(tp):
        if f.name in value:
            kwargs[f.name] = at.into(f.name).read(hints[f.name], value[f.name])
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise at.into(f.name).fail("missing required field")
    build = cast(Callable[..., Any], tp)  # a dataclass type (dataclasses.fields above), called with its fields
    return build(**kwargs)


def _tuple(args: tuple[Any, ...], value: Any, at: _Place) -> tuple[Any, ...]:
    if not isinstance(value, (list, tuple)):
        raise at.fail(f"expected a list, got {type(value).__name__}")
    if len(args) == 2 and args[1] is Ellipsis:
        return tuple(at.item(i).read(args[0], v) for i, v in enumerate(value))
    if len(value) != len(args):
        raise at.fail(f"expected a list of {len(args)} numbers, got {len(value)}")
    return tuple(at.item(i).read(a, v) for i, (a, v) in enumerate(zip(args, value)))


def _mapping(value_type: Any, value: Any, at: _Place) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise at.fail(f"expected a mapping, got {type(value).__name__}")
    return {str(k): at.into(str(k)).read(value_type, v) for k, v in value.items()}


def _too_large(value: Any) -> str:
    return f"out of range: {value} (numbers are at most {MAX_MAGNITUDE:.0e} in size)"


def _float(value: Any, at: _Place) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise at.fail(f"expected a number, got {_short(value)}")
    if isinstance(value, int) and abs(value) > MAX_MAGNITUDE:
        raise at.fail(_too_large(_short(value)))
    if not math.isfinite(value):
        raise at.fail(f"expected a finite number, got {value!r}")
    if abs(value) > MAX_MAGNITUDE:
        raise at.fail(_too_large(repr(value)))
    return float(value)


def _int(value: Any, at: _Place) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise at.fail(f"expected an integer, got {_short(value)}")
    if at.bounded and abs(value) > MAX_MAGNITUDE:
        raise at.fail(_too_large(_short(value)))
    return value


def _bool(value: Any, at: _Place) -> bool:
    if not isinstance(value, bool):
        raise at.fail(f"expected true or false, got {value!r}")
    return value


def _str(value: Any, at: _Place) -> str:
    if not isinstance(value, str):
        raise at.fail(f"expected a string, got {value!r}")
    return value


def _path(value: Any, at: _Place) -> Path:
    if not isinstance(value, str) or not value:
        raise at.fail(f"expected a path, got {_short(value)}")
    return Path(value)


def _hex_bytes(value: Any, at: _Place) -> bytes:
    if isinstance(value, str):
        try:
            return bytes.fromhex(value)
        except ValueError:
            pass
    raise at.fail(f"expected bytes as hexadecimal digits, got {_short(value)}")


_SCALARS: dict[Any, Callable[[Any, _Place], Any]] = {
    float: _float,
    int: _int,
    bool: _bool,
    str: _str,
    Path: _path,
    bytes: _hex_bytes,
}
"""The scalar types a schema may hold, each with its check (a path is a string, bytes are hexadecimal digits: the
form :func:`tssac_core.sim.settings_json.plain` gives them)."""


def _short(value: Any, max_chars: int = 40) -> str:
    """``repr(value)`` cut to ``max_chars`` (a 4,000-digit integer makes no error line readable)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10**max_chars:
        return f"an integer of {len(str(abs(value)))} digits"
    text = repr(value)
    return text if len(text) <= max_chars else text[: max_chars - 3] + "..."


def _join(where: str, name: str) -> str:
    return f"{where}.{name}" if where else name
