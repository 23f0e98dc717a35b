"""A benchmark run from the README writes its figures where the user says, by default outside the checkout: never over
the committed figures in benchmarks/results/ (benchmarks/output.py)."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.output import RESULTS_VARIABLE, default_json, results_dir  # noqa: E402


def test_the_default_results_directory_is_outside_the_checkout(monkeypatch, tmp_path):
    monkeypatch.delenv(RESULTS_VARIABLE, raising=False)
    assert not results_dir().resolve().is_relative_to(ROOT)
    monkeypatch.setenv(RESULTS_VARIABLE, str(tmp_path))
    assert default_json("env") == tmp_path / "env.json"


def test_no_benchmark_writes_into_the_checkout_by_default():
    """No default of a benchmark's code names benchmarks/results/ (its docstrings may, as an explicit --json)."""
    offenders = []
    for path in sorted((ROOT / "benchmarks").rglob("*.py")):
        tree = ast.parse(path.read_text())
        docstrings = {
            id(node.body[0].value)
            for node in ast.walk(tree)
            if isinstance(node, ast.Module | ast.FunctionDef | ast.ClassDef)
            and node.body
            and isinstance(node.body[0], ast.Expr)
        }
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
                if "benchmarks/results" in node.value:
                    offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}: {node.value!r}")
    assert offenders == []


def test_a_benchmark_run_leaves_the_tree_as_it_was(tmp_path):
    """bench_help (the quickest) with no --json: the tracked files unchanged, the figures in the results directory."""
    env = dict(os.environ, TSSAC_BENCH_RESULTS=str(tmp_path))
    before = subprocess.run(["git", "status", "--porcelain"], cwd=ROOT, capture_output=True, text=True).stdout
    done = subprocess.run(
        [sys.executable, "benchmarks/bench_help.py", "--runs", "1"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "help.json").is_file() and f"wrote {tmp_path / 'help.json'}" in done.stdout
    after = subprocess.run(["git", "status", "--porcelain"], cwd=ROOT, capture_output=True, text=True).stdout
    assert after == before


def test_a_sitl_row_counts_the_companions_unprotected_steps() -> None:
    """bench_adversaries' SITL rows sum each companion's ``shield.unprotected_steps`` (None when none reported)."""
    from benchmarks.bench_adversaries import unprotected_steps

    def mission(*counts: int | None) -> dict[str, object]:
        roles = ("decoy", "detect", "strike")
        return {
            "companions": {
                r: {"shield": None if n is None else {"unprotected_steps": n}} for r, n in zip(roles, counts)
            }
        }

    assert unprotected_steps([mission(0, 3, 0), mission(2, 0, None)]) == 5
    assert unprotected_steps([mission(None, None, None)]) is None
    assert unprotected_steps([]) is None


def test_the_monitored_team_benchmark_flies_the_same_missions_alone_and_through_the_monitor(tmp_path: Path) -> None:
    """bench_monitored_team: per team and wind a row alone and a row through the monitor, on the same layouts and
    airframes; the file written after every row; a bad wind is one line."""
    import json

    from benchmarks.bench_monitored_team import main
    from tssac_core.common.cli import run

    out = tmp_path / "m.json"
    args = ["--models", str(ROOT / "models" / "tssac"), "--episodes", "2", "--seed", "5", "--wind-m-s", "0"]
    assert run(main, [*args, "--json", str(out)]) == 0
    rows = json.loads(out.read_text())["rows"]
    assert [(r["wind_m_s"], r["monitor"], r["missions"]) for r in rows] == [(0.0, False, 2), (0.0, True, 2)]
    assert "interventions_per_uav_mission" in rows[1] and "interventions_per_uav_mission" not in rows[0]
    assert run(main, [*args[:-1], "80", "--json", str(out)]) == 2
