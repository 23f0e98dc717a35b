"""Reading a YAML file for a command: any problem becomes one error line naming the file."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml

FileError = Callable[[str, str, str], Exception]
"""Builds the caller's error from (file, field path, problem)."""


def read_yaml(path: str | Path, error: FileError) -> Any:
    """The parsed content of ``path``; an unreadable file or invalid YAML raises ``error(file, "", problem)``."""
    source = str(path)
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise error(source, "", f"cannot read file ({exc.strerror or exc})") from None
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
