"""What a run's ``metrics.csv`` says about how fast a role learned (the transfer figures and the curves)."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

Rows = list[dict[str, str]]
"""A run's metrics.csv rows (one per role and epoch), as csv.DictReader reads them."""


def read_metrics(run: Path) -> Rows:
    """The rows of ``run/metrics.csv`` (none if there is no such file)."""
    path = run / "metrics.csv"
    if not path.is_file():
        return []
    with path.open() as fh:
        return list(csv.DictReader(fh))


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return math.nan


def steps_to_threshold(rows: Rows, role: str, threshold: float) -> tuple[int | None, int]:
    """(env_steps at the end of the first epoch with task_success >= threshold, or None; the role's total env_steps)."""
    sel = sorted((r for r in rows if r["role"] == role), key=lambda r: int(r["epoch"]))
    total = int(_number(sel[-1]["env_steps"])) if sel else 0
    for r in sel:
        if _number(r["task_success"]) >= threshold:
            return int(_number(r["env_steps"])), total
    return None, total


def mean_task_success(rows: Rows, role: str) -> float:
    """The role's training task success averaged over its epochs: how early it learned, in one number
    that also compares runs that never reach the threshold (the area under its learning curve)."""
    values = [v for r in rows if r["role"] == role and math.isfinite(v := _number(r["task_success"]))]
    return float(np.mean(values)) if values else math.nan
