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


def typed_value(tp: Any, value: Any, where: str, source: str, error: FileError) -> Any:
    """``value`` (plain YAML data) as type ``tp`` (a dataclass, an enum by its values, tuple, dict, optional, float,
    int, bool or str), checked all the way down; the first problem raises ``error(source, field path, problem)``.
    Scenario files, preset files and grid files are read with it, so a value is judged, and its problem worded, the
    same in each."""
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return typed_value(inner, value, where, source, error)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        allowed = [str(member.value) for member in tp]
        if not isinstance(value, str) or value not in allowed:
            raise error(source, where, f"expected one of {', '.join(allowed)}, got {_short(value)}")
        return tp(value)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise error(source, where, f"expected a mapping, got {type(value).__name__}")
        hints = typing.get_type_hints(tp)
        names = {f.name for f in dataclasses.fields(tp)}
        for key in value:
            if key not in names:
                raise error(source, _join(where, str(key)), f"unknown key (allowed: {', '.join(sorted(names))})")
        kwargs = {}
        for f in dataclasses.fields(tp):
            if f.name in value:
                kwargs[f.name] = typed_value(hints[f.name], value[f.name], _join(where, f.name), source, error)
            elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise error(source, _join(where, f.name), "missing required field")
        build = cast(Callable[..., Any], tp)  # a dataclass type (dataclasses.fields above), called with its fields
        return build(**kwargs)
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise error(source, where, f"expected a list, got {type(value).__name__}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(typed_value(args[0], v, f"{where}[{i}]", source, error) for i, v in enumerate(value))
        if len(value) != len(args):
            raise error(source, where, f"expected a list of {len(args)} numbers, got {len(value)}")
        return tuple(typed_value(a, v, f"{where}[{i}]", source, error) for i, (a, v) in enumerate(zip(args, value)))
    if origin is dict:
        if not isinstance(value, dict):
            raise error(source, where, f"expected a mapping, got {type(value).__name__}")
        return {str(k): typed_value(args[1], v, _join(where, str(k)), source, error) for k, v in value.items()}
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise error(source, where, f"expected a number, got {_short(value)}")
        if isinstance(value, int) and abs(value) > MAX_MAGNITUDE:
            raise error(
                source, where, f"out of range: {_short(value)} (numbers are at most {MAX_MAGNITUDE:.0e} in size)"
            )
        if not math.isfinite(value):
            raise error(source, where, f"expected a finite number, got {value!r}")
        if abs(value) > MAX_MAGNITUDE:
            raise error(source, where, f"out of range: {value!r} (numbers are at most {MAX_MAGNITUDE:.0e} in size)")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise error(source, where, f"expected an integer, got {_short(value)}")
        if abs(value) > MAX_MAGNITUDE:
            raise error(
                source, where, f"out of range: {_short(value)} (numbers are at most {MAX_MAGNITUDE:.0e} in size)"
            )
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise error(source, where, f"expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise error(source, where, f"expected a string, got {value!r}")
        return value
    raise TypeError(f"unsupported schema type {_type_name(tp)} at {where}")  # a bug in the schema


def _short(value: Any, max_chars: int = 40) -> str:
    """``repr(value)`` cut to ``max_chars`` (a 4,000-digit integer makes no error line readable)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10**max_chars:
        return f"an integer of {len(str(abs(value)))} digits"
    text = repr(value)
    return text if len(text) <= max_chars else text[: max_chars - 3] + "..."


def _join(where: str, name: str) -> str:
    return f"{where}.{name}" if where else name
