"""A configuration dataclass as its own schema: each field's help, range, choices and rule are written once, beside its
default (`option`), and read by every front end: the command line's flags are generated from them (`add_flags`), a
config file's values are checked by them (`check_field`), and the dataclass checks itself with them (`check_fields`,
from its ``__post_init__``). A refused value is an `OptionError` naming the field and the problem; each front end
names the field its own way (``--hard-layouts``, ``algos[1].hard_layouts``) before the same problem."""

from __future__ import annotations

import argparse
import dataclasses
import enum
import math
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any


class OptionError(ValueError):
    """A value that a field's option refuses: ``field`` (its name in the dataclass) and ``problem`` (one line)."""

    def __init__(self, field: str, problem: str) -> None:
        super().__init__(f"{field}: {problem}")
        self.field = field
        self.problem = problem


@dataclass(frozen=True)
class Option:
    """What a field takes and how the command line offers it."""

    help: str
    minimum: float | None = None
    maximum: float | None = None
    choices: tuple[str, ...] = ()
    """The words it takes (an empty value, None or "", stands for the default where the field allows it)."""
    rule: Callable[[Any], str | None] | None = None
    """A further check of the value alone: its problem, or None."""
    parse: Callable[[str], Any] | None = None
    """The command line's text -> the value (default: the field's type)."""
    metavar: str | None = None


def option(default: Any, help: str, **settings: Any) -> Any:
    """A dataclass field with ``default`` and its `Option` (``settings``: the Option's other fields)."""
    return dataclasses.field(default=default, metadata={"option": Option(help, **settings)})


def options(cls: type) -> dict[str, Option]:
    """The options of a dataclass, by field name, in field order."""
    return {f.name: f.metadata["option"] for f in dataclasses.fields(cls) if "option" in f.metadata}


def flag_name(field: str) -> str:
    """The command-line flag of a field: ``hard_layouts`` -> ``--hard-layouts``."""
    return "--" + field.replace("_", "-")


def check_field(cls: type, name: str, value: Any) -> Any:
    """``value`` if the option of field ``name`` of ``cls`` takes it; OptionError otherwise."""
    opt = options(cls)[name]
    if opt.choices and value not in (None, "") and str(value) not in opt.choices:
        raise OptionError(name, f"expected one of {', '.join(opt.choices)}, got {value!r}")
    if opt.minimum is not None or opt.maximum is not None:
        problem = _range_problem(opt.minimum, opt.maximum, value)
        if problem:
            raise OptionError(name, problem)
    problem = opt.rule(value) if opt.rule is not None else None
    if problem:
        raise OptionError(name, problem)
    return value


def check_fields(config: Any) -> None:
    """Every option field of the dataclass instance ``config``, checked (`check_field`)."""
    for name in options(type(config)):
        check_field(type(config), name, getattr(config, name))


def _range_problem(low: float | None, high: float | None, value: Any) -> str | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"expected a number, got {value!r}"
    inside = not math.isnan(value) and (low is None or value >= low) and (high is None or value <= high)
    if inside:
        return None
    if (low, high) == (0, 1):
        return f"expected a fraction in [0, 1], got {_shown(value)}"
    if low is not None and high is not None:
        return f"expected a value in [{_shown(low)}, {_shown(high)}], got {_shown(value)}"
    return f"must be >= {_shown(low)}, got {_shown(value)}" if low is not None else f"must be <= {_shown(high)}"


def _shown(value: Any) -> str:
    """A value as help and errors write it: floats short, enums and sequences as their words."""
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, enum.Enum):
        return str(value.value)
    if isinstance(value, (tuple, list)):
        return ",".join(_shown(v) for v in value)
    return str(value)


def add_flags(parser: argparse.ArgumentParser, cls: type, defaults: Mapping[str, Any] | None = None) -> None:
    """A flag for every option field of ``cls``: its type, choices, help and default (``defaults`` first, e.g. a
    preset's values; then the field's own), the default said in the help."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for name, opt in options(cls).items():
        default = (defaults or {}).get(name, fields[name].default)
        shown = f" (default: {_shown(default)})" if default not in (None, "", ()) else ""
        parser.add_argument(
            flag_name(name),
            dest=name,
            type=opt.parse or _parser_type(hints[name]),
            choices=list(opt.choices) or None,
            default=default,
            metavar=opt.metavar,
            help=opt.help + shown,
        )


def _parser_type(hint: Any) -> Callable[[str], Any]:
    """argparse's ``type`` for a field's annotation: int, float or str (words: their choices are checked)."""
    for kind in (int, float):
        if hint is kind:
            return kind
    return str


def flag_values(namespace: argparse.Namespace, cls: type) -> dict[str, Any]:
    """The option fields' values of a parsed command line."""
    return {name: getattr(namespace, name) for name in options(cls)}
