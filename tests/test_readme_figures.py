"""Every figure the README's results table quotes is the JSON its row cites: success with its 95% interval and mean
cost (with its interval where the JSON has one), printed as the table prints them; and the JSON is the command's
(its seed and its number of missions)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest

from tssac_core.common.stats import wilson_interval

ROOT = Path(__file__).resolve().parent.parent
JSON_CELL = re.compile(r"`([^`]+\.json)`(?: \(([^)]*)\))?")
"""A cited JSON file, optionally followed by the keys that lead to the figures inside it: ``(`runs`, `jsbsim`)``."""


def results_table(readme: str) -> list[dict[str, str]]:
    """The rows of the table under ``## Results``, as {column: cell}."""
    section = readme.split("\n## Results\n", 1)[1].split("\n## ", 1)[0]
    lines = [line for line in section.splitlines() if line.startswith("|")]
    header = [cell.strip() for cell in lines[0].strip("|").split("|")]
    rows = []
    for line in lines[2:]:
        cells = [cell.strip() for cell in re.split(r"(?<!\\)\|", line.strip().strip("|"))]
        assert len(cells) == len(header), line
        rows.append(dict(zip(header, cells, strict=True)))
    return rows


def cited(cell: str) -> list[dict[str, Any]]:
    """The figures of each JSON a cell cites (``a.json / b.json``: the monitor off, then on)."""
    figures = []
    for path, keys in JSON_CELL.findall(cell):
        data = json.loads((ROOT / path).read_text(encoding="utf-8"))
        for key in re.findall(r"`([^`]+)`", keys):
            data = data[key]
        figures.append(data)
    return figures


def success_printed(figures: dict[str, Any]) -> str:
    rate = figures["success_rate"]
    if "success_interval95" in figures:
        low, high = figures["success_interval95"]
    else:  # a campaign file keeps the rate and the count: the interval is Wilson's, as everywhere else
        n = figures.get("episodes", figures.get("missions"))
        interval = wilson_interval(round(rate * n), n)
        low, high = interval.low, interval.high
    return f"{100 * rate:.1f}% ({100 * low:.1f}-{100 * high:.1f})"


def cost_printed(figures: dict[str, Any]) -> str:
    text = f"{figures['mean_cost']:.2f}"
    if "mean_cost_interval95" in figures:
        low, high = figures["mean_cost_interval95"]
        text += f" ({low:.2f}-{high:.2f})"
    return text


def flag(command: str, name: str) -> int | None:
    match = re.search(rf"--{name} (\d+)", command)
    return int(match.group(1)) if match else None


ROWS = results_table((ROOT / "README.md").read_text(encoding="utf-8"))


def test_the_table_is_read() -> None:
    """The parser finds the table and every row cites a JSON: a row without one fails here."""
    assert len(ROWS) >= 8
    for row in ROWS:
        assert JSON_CELL.search(row["JSON"]), f"no JSON cited for {row['command']}"


@pytest.mark.parametrize("row", ROWS, ids=lambda row: row["command"].split("--seed ")[-1].split()[0])
def test_a_quoted_figure_is_its_json(row: dict[str, str]) -> None:
    files = cited(row["JSON"])
    success = row["mission success"].split(" / ")
    cost = row["mean cost"].split(" / ")
    assert len(files) == len(success) == len(cost), row
    command = row["command"].strip("`")
    for figures, success_cell, cost_cell in zip(files, success, cost, strict=True):
        assert success_cell == success_printed(figures)
        assert cost_cell == cost_printed(figures)
        n = figures.get("episodes", figures.get("missions"))
        assert n == (flag(command, "episodes") or flag(command, "missions")), (n, command)
        if "seed" in figures:
            assert figures["seed"] == flag(command, "seed"), (figures["seed"], command)


def test_an_edited_figure_is_found() -> None:
    """The negative control: one digit changed in a quoted figure no longer matches its JSON."""
    row = next(r for r in ROWS if "eval_generalization" in r["JSON"])
    figures = cited(row["JSON"])[0]
    assert row["mission success"] == success_printed(figures)
    edited = row["mission success"].replace("99.1", "99.2", 1)
    assert edited != success_printed(figures)
