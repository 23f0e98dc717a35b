"""Where a benchmark writes its figures: ``--json FILE`` when given, else ``NAME.json`` in a results directory outside
the checkout (``$TSSAC_BENCH_RESULTS``, default ``tssac-benchmarks`` under the system's temporary directory), so that
running a benchmark never rewrites a tracked file. The committed figures that benchmarks/RESULTS.md cites are in
benchmarks/results/ and change only when asked: ``--json benchmarks/results/NAME.json``."""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path
from typing import Any

RESULTS_VARIABLE = "TSSAC_BENCH_RESULTS"
COMMITTED = Path("benchmarks") / "results"
"""The committed figures' directory, in the checkout."""


def results_dir() -> Path:
    """The default results directory (module docstring)."""
    return Path(os.environ.get(RESULTS_VARIABLE) or Path(tempfile.gettempdir()) / "tssac-benchmarks")


def default_json(name: str) -> Path:
    return results_dir() / f"{name}.json"


def add_json_option(parser: argparse.ArgumentParser, name: str) -> None:
    """``--json FILE``, default :func:`default_json` of ``name``."""
    parser.add_argument(
        "--json",
        type=Path,
        default=default_json(name),
        help=f"write the figures here (default {default_json(name)}; the committed ones: {COMMITTED / name}.json)",
    )


def write_figures(path: Path, data: Any) -> Path:
    """``data`` as indented JSON at ``path`` (its directory made); prints where it went."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=2) + "\n")
    print(f"wrote {path}")
    return path
