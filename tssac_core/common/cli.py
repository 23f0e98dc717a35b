"""What every command line shares: one clear line and a non-zero exit on bad input."""

from __future__ import annotations

import json
import logging
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from tssac_core.common.errors import InputError
from tssac_core.common.files import replace_durably

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130


class UsageError(InputError):
    """A command-line argument a user can fix; the message is the one line they see."""


BAD_INPUT = (InputError, OSError)
"""What a command reports in one line with exit code 2: bad input, and files it cannot read or write."""


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
    """Write JSON atomically (a partial file is never left behind)."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(target.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    replace_durably(tmp, target)
