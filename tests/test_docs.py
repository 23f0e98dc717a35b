"""The docs name only what exists: every repository path and project module written in the Markdown pages (history in
the journal aside) and in the packages' docstrings and comments exists, and every relative link resolves."""

from __future__ import annotations

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
HISTORY = {"docs/journal.md"}
"""The journal tells what was: it names files that are gone on purpose."""


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


def stale_names(text: str, here: Path = ROOT) -> list[str]:
    """The paths and modules ``text`` names that do not exist (a path may be the repository's or ``here``'s)."""
    stale = []
    for path in PATH.findall(text):
        path = path.rstrip(".")
        if not PLACEHOLDER.search(path) and not (ROOT / path).exists() and not (here / path).exists():
            stale.append(path)
    stale += [m for m in MODULE.findall(text) if not module_exists(m.rstrip("."))]
    return stale


def test_the_checker_finds_a_stale_name() -> None:
    """The negative control: names that are gone are found, names that exist and patterns are not."""
    text = "see `configs/shipped.yaml`, `tssac_core/observation.py` and tssac_core.sim.routes_old.field"
    assert stale_names(text) == ["configs/shipped.yaml", "tssac_core/observation.py", "tssac_core.sim.routes_old.field"]
    fine = "`tssac_core/sim/world.py`, tssac_core.sim.world.World.step, results/runs/run{0,1}, scenarios/NAME.yaml"
    assert stale_names(fine) == []


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
    stale = {str(p.relative_to(ROOT)): s for p in code_files() if (s := stale_names(p.read_text(encoding="utf-8")))}
    assert not stale, stale
