"""Reading a YAML file for a command: any problem becomes one error line naming the file."""

from __future__ import annotations

import codecs
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml

FileError = Callable[[str, str, str], Exception]
"""Builds the caller's error from (file, field path, problem)."""

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
