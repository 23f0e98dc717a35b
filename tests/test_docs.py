"""The docs name only what exists: every repository path and project module written in the Markdown pages (history in
the journal aside) and in the packages' docstrings and comments exists, and every relative link resolves."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
TOP_DIRS = (
    "tssac_core",
    "sim_vehicles",
    "mavlink_bridge",
    "tests",
    "benchmarks",
    "configs",
    "scenarios",
    "docs",
    "models",
    "experiments",
    "examples",
    "results",
)
PACKAGES = ("tssac_core", "sim_vehicles", "mavlink_bridge")
PATH = re.compile(rf"(?<![\w./-])((?:{'|'.join(TOP_DIRS)})/[\w./-]*\w)(?![\w./{{<*-])")
"""A repository path: a top-level directory, then path characters (a path followed by a placeholder such as
``seed{0,1}``, ``<role>`` or ``*`` is a pattern, not a name)."""
MODULE = re.compile(rf"(?<![\w./])((?:{'|'.join(PACKAGES)})(?:\.[a-z_]\w*)+)")
"""A dotted project module, possibly followed by an attribute or two (``tssac_core.sim.world.World.step``)."""
LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")
PLACEHOLDER = re.compile(r"(?:^|[/_-])(?:N|K|NAME|FILE|DIR|X|ROLE|SEED)(?:[/._-]|$)")
RELATIVE = re.compile(r"`((?:\.\./)*[\w.-]+(?:/[\w.-]+)+(?:\.(?:json|md|py|yaml|csv|png|txt|npz|pt|onnx)|/))`")
"""A path written relative to its page (``full-budget/table4.md``, ``../../results/x/``): a file of the project's
kinds, or a folder."""
EXTERNAL = {"shared/seed/tssac-paper.txt", "safe_rl/pg/agents.py"}
"""Files of other trees that pages cite: the paper's text beside the checkout, safety-starter-agents' source."""
HISTORY = {"docs/journal.md"}
"""The journal tells what was: it names files that are gone on purpose."""
FIGURE_PAGES = ("README.md", "models/tssac/README.md", "results/README.md", "benchmarks/RESULTS.md")


def markdown_pages() -> list[Path]:
    pages = [p for p in ROOT.rglob("*.md") if not ({".venv", ".git", "runs"} & set(p.parts))]
    return [p for p in pages if str(p.relative_to(ROOT)) not in HISTORY]


def code_files() -> list[Path]:
    return [p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")]


def module_exists(name: str) -> bool:
    """``a.b.c`` names a module or package, or a name defined in one (and, at most, an attribute of that name)."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        base = ROOT.joinpath(*parts[:k])
        source = base.with_suffix(".py") if base.with_suffix(".py").is_file() else base / "__init__.py"
        if source.is_file():
            rest = parts[k:]
            if not rest or rest[0].startswith("__"):  # the module itself, or a module attribute (``__file__``)
                return True
            return len(rest) <= 2 and re.search(rf"\b{rest[0]}\b", source.read_text()) is not None
    return False


def stale_names(text: str, here: Path = ROOT, relative: bool = True) -> list[str]:
    """The paths and modules ``text`` names that do not exist (a path may be the repository's or ``here``'s; with
    ``relative``, a Markdown page's, paths relative to it too: in code, ``run_dir/config.json`` names a variable's)."""
    stale = []
    for path in PATH.findall(text):
        path = path.rstrip(".")
        if not PLACEHOLDER.search(path) and not (ROOT / path).exists() and not (here / path).exists():
            stale.append(path)
    stale += [m for m in MODULE.findall(text) if not module_exists(m.rstrip("."))]
    for path in RELATIVE.findall(text) if relative else []:
        if PATH.fullmatch(path) or path in EXTERNAL or PLACEHOLDER.search(path):
            continue  # a repository path is checked above
        if not (here / path).exists() and not (ROOT / path).exists():
            stale.append(path)
    return stale


def test_the_checker_finds_a_stale_name() -> None:
    """The negative control: names that are gone are found, names that exist and patterns are not."""
    text = "see `configs/shipped.yaml`, `tssac_core/observation.py` and tssac_core.sim.routes_old.field"
    assert stale_names(text) == ["configs/shipped.yaml", "tssac_core/observation.py", "tssac_core.sim.routes_old.field"]
    fine = "`tssac_core/sim/world.py`, tssac_core.sim.world.World.step, results/runs/run{0,1}, scenarios/NAME.yaml"
    assert stale_names(fine) == []
    here = ROOT / "results" / "shipped-team" / "grid-tssac-seed2"
    gone = ["../../results/recipe-trials/hard50/", "half-budget-layouts/ppo_lag-seed0.json"]
    relative = f"`{gone[0]}`, `{gone[1]}`, `../seeds/seed1_random_1000.json`"
    assert stale_names(relative, here) == gone
    assert stale_names("`full-budget/half-budget-layouts/ppo_lag-seed0.json`, `tssac/Decoy-v0`", ROOT / "results") == []


@pytest.mark.parametrize("page", markdown_pages(), ids=lambda p: str(p.relative_to(ROOT)))
def test_a_page_names_only_what_exists(page: Path) -> None:
    text = page.read_text(encoding="utf-8")
    stale = stale_names(text, page.parent)
    for link in LINK.findall(text):
        if "://" in link or link.startswith("mailto:"):
            continue
        if not (page.parent / link).exists():
            stale.append(f"link {link}")
    assert not stale, stale


def test_the_code_names_only_what_exists() -> None:
    stale = {
        str(p.relative_to(ROOT)): s
        for p in code_files()
        if (s := stale_names(p.read_text(encoding="utf-8"), relative=False))
    }
    assert not stale, stale


def test_the_index_lists_every_page() -> None:
    """docs/README.md links every page in docs/ and every figure page."""
    index = (ROOT / "docs" / "README.md").read_text(encoding="utf-8")
    linked = {(ROOT / "docs" / link).resolve() for link in LINK.findall(index)}
    pages = [p for p in (ROOT / "docs").glob("*.md") if p.name != "README.md"] + [ROOT / f for f in FIGURE_PAGES]
    missing = [str(p.relative_to(ROOT)) for p in pages if p.resolve() not in linked]
    assert not missing, missing


RESULT_TABLE = "| where | scenario, missions | command | monitor | mission success | mean cost | JSON |"


def quoted(summary: dict) -> tuple[str, str]:
    """How the README writes a results JSON's success and mean cost, with their 95% intervals."""
    low, high = summary["success_interval95"]
    cost_low, cost_high = summary["mean_cost_interval95"]
    return (
        f"{100 * summary['success_rate']:.1f}% ({100 * low:.1f}-{100 * high:.1f})",
        f"{summary['mean_cost']:.2f} ({cost_low:.2f}-{cost_high:.2f})",
    )


def readme_result_rows() -> list[list[str]]:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    table = text[text.index(RESULT_TABLE) :].split("\n\n")[0].splitlines()[2:]
    return [[cell.strip() for cell in line.strip("|").split(" | ")] for line in table]


def test_every_figure_the_readme_quotes_is_the_json_it_cites() -> None:
    rows = readme_result_rows()
    checked = 0
    for where, _, _, _, success, cost, cited in rows:
        paths = re.findall(r"`([\w./-]+\.json)`", cited)
        if "(`" in cited:  # a figure inside a benchmark's JSON (its key path given): not a results JSON
            continue
        assert len(paths) == len(success.split(" / ")) == len(cost.split(" / ")), where
        for path, s, c in zip(paths, success.split(" / "), cost.split(" / "), strict=True):
            assert (s, c) == quoted(json.loads((ROOT / path).read_text())), f"{where}: {path}"
            checked += 1
    assert checked >= 8, checked


def test_the_figure_check_catches_a_figure_that_is_not_the_jsons() -> None:
    summary = {"success_rate": 0.9983, "success_interval95": [0.99728, 0.99894], "mean_cost": 0.0418}
    summary["mean_cost_interval95"] = [0.0147, 0.0755]
    assert quoted(summary) == ("99.8% (99.7-99.9)", "0.04 (0.01-0.08)")
    assert quoted({**summary, "success_rate": 0.995})[0] == "99.5% (99.7-99.9)"
