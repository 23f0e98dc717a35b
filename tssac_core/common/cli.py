"""What every command line shares: one clear line and a non-zero exit on bad input."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from tssac_core.common.errors import InputError
from tssac_core.common.files import write_text_safely

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130


class UsageError(InputError):
    """A command-line argument a user can fix; the message is the one line they see."""


class UsageParser(argparse.ArgumentParser):
    """An argument parser whose errors are a :class:`UsageError` (the command's runner prints it as one line and
    exits 2) instead of argparse's usage block and exit."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(f"{message} (see --help)")


BAD_INPUT = (InputError, OSError)
"""What a command reports in one line with exit code 2: bad input, and files it cannot read or write."""


SEED_MAX = 2**63 - 1
"""The largest seed a command takes: numpy's generators take any non-negative integer, torch's ``manual_seed`` one
below 2**64; a mission's seed is the first one plus its index, so the range leaves room for any campaign."""


def command_description(doc: str | None) -> str:
    """A command's ``--help`` description from its module docstring: the whole first paragraph as one line, without
    reST's double backquotes (the first line alone cut sentences in half)."""
    first = (doc or "").strip().split("\n\n")[0]
    return " ".join(first.replace("``", "").split())


def seed_arg(text: str) -> int:
    """argparse's ``type`` for ``--seed``: a whole number from 0 to :data:`SEED_MAX` (numpy refuses a negative seed
    with a traceback deep in a mission, long after the command line was read)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid seed {text!r}: a whole number from 0 to {SEED_MAX}") from None
    if not 0 <= value <= SEED_MAX:
        raise argparse.ArgumentTypeError(f"invalid seed {value}: a whole number from 0 to {SEED_MAX}")
    return value


def bad_input_line(exc: Exception) -> str:
    """The one line a user sees for a :data:`BAD_INPUT` error."""
    if isinstance(exc, OSError):
        return f"{exc.filename or ''}: {exc.strerror or exc}"
    return str(exc)


def run(main: Callable[[Sequence[str] | None], int], argv: Sequence[str] | None = None) -> int:
    """Run a command's ``main``: known errors become one line on stderr and exit code 2."""
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        return main(argv)
    except BAD_INPUT as exc:
        print(f"error: {bad_input_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def write_json(path: str | Path, data: Any) -> None:
    """Write JSON: atomically to a regular file (a partial file is never left behind), in place to a named pipe or a
    character device (``--json /dev/stdout``), through the user's own links (:func:`write_text_safely`)."""
    write_text_safely(Path(path), json.dumps(data, indent=2) + "\n")
