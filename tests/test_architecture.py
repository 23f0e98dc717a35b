"""The layout's rules, checked on the source: no import cycles, who may import whom, and what the
companion and ``import tssac_core`` pull in (each in a fresh interpreter)."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("tssac_core", "mavlink_bridge", "sim_vehicles")


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(path: Path) -> set[str]:
    """Every module that ``path`` imports, at any depth of the file (function-level imports count too).
    ``from pkg import name`` counts as importing ``pkg`` and ``pkg.name`` (the caller keeps the modules)."""
    tree = ast.parse(path.read_text())
    found: set[str] = set()
    package = module_name(path) if path.name == "__init__.py" else module_name(path).rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(
                    package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else [])
                )
            found.add(base)
            found |= {f"{base}.{alias.name}" for alias in node.names}  # `from pkg import module`
    return found


def project_graph() -> dict[str, set[str]]:
    files = [p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py") if p.name != "__main__.py"]
    modules = {module_name(p): p for p in files}
    graph = {}
    for name, path in modules.items():
        found = imports_of(path) & set(modules)
        # `from pkg import module` runs pkg/__init__ first, as every import of a submodule does: not an edge to pkg.
        graph[name] = {m for m in found if m != name and not any(other.startswith(m + ".") for other in found)}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt) :] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def test_no_import_cycles():
    graph = project_graph()
    assert len(graph) > 40  # the walk found the packages
    assert find_cycle(graph) is None, " -> ".join(find_cycle(graph) or [])


def test_the_cycle_finder_finds_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]


@pytest.mark.parametrize(
    ("package", "forbidden"),
    [
        ("tssac_core", ("pymavlink", "sim_vehicles", "mavlink_bridge")),
        ("sim_vehicles", ("mavlink_bridge",)),
        ("mavlink_bridge", ("sim_vehicles",)),
    ],
)
def test_who_may_import_whom(package: str, forbidden: tuple[str, ...]):
    offenders = sorted(
        f"{module_name(p)} imports {m}"
        for p in (ROOT / package).rglob("*.py")
        for m in imports_of(p)
        if m.split(".")[0] in forbidden
    )
    assert not offenders, offenders


def modules_after(statement: str) -> set[str]:
    code = f"import sys\n{statement}\nprint(' '.join(sorted(m.split('.')[0] for m in sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    return set(out.stdout.split())


def test_the_companion_imports_neither_torch_nor_gymnasium():
    loaded = modules_after("import mavlink_bridge.companion.cli, mavlink_bridge.companion.machine")
    assert "pymavlink" in loaded and "numpy" in loaded  # it did import the companion
    assert "torch" not in loaded
    assert "gymnasium" not in loaded


def test_importing_tssac_core_imports_no_gymnasium_but_the_env_registers_itself():
    assert "gymnasium" not in modules_after("import tssac_core")
    code = (
        "import gymnasium as gym\n"
        "env = gym.make('tssac_core.sim.env:tssac/Detect-v0')\n"
        "print(env.observation_space.shape)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr


def test_the_monitor_sits_below_every_room():
    """The runtime-assurance monitor is used by the batched world, the scenario's start check and the companion:
    it imports nothing from the project, so each of them may import it."""
    offenders = sorted(
        f"{module_name(p)} imports {m}"
        for p in (ROOT / "tssac_core" / "assurance").rglob("*.py")
        for m in imports_of(p)
        if m.split(".")[0] in PACKAGES
    )
    assert not offenders, offenders


ROOMS = (
    ("tssac_core.common", "tssac_core.assurance", "tssac_core.wire"),
    ("tssac_core.sim",),
    ("tssac_core.algos",),
    ("tssac_core.cli",),
    ("tssac_core.deploy", "tssac_core.parallel", "tssac_core.reporting"),
    ("tssac_core.train", "tssac_core.experiments"),
    ("tssac_core.evaluate",),
)
"""tssac_core's rooms (its subpackages, and its two top-level modules), lowest first: a room imports only rooms of lower
layers. The one pair that imports each other: ``train --seeds`` runs its seeds on the grid's executors, and the grid
runs ``train``."""
MUTUAL = {("tssac_core.train", "tssac_core.experiments"), ("tssac_core.experiments", "tssac_core.train")}


def room_of(module: str) -> str:
    return ".".join(module.split(".")[:2])


def test_every_module_has_a_room():
    """At tssac_core's top level only the package face and the two modules every command goes through: the rest
    lives in a subpackage that names what it is."""
    loose = sorted(p.name for p in (ROOT / "tssac_core").glob("*.py"))
    assert loose == ["__init__.py", "cli.py", "evaluate.py"], loose
    layered = {room for layer in ROOMS for room in layer}
    rooms = {room_of(m) for m in project_graph() if m.startswith("tssac_core.")}
    assert rooms == layered, rooms ^ layered  # a new room is given its layer here


def test_rooms_import_downward_only():
    layer = {room: k for k, rooms in enumerate(ROOMS) for room in rooms}
    offenders = sorted(
        f"{a} imports {b}"
        for a, targets in project_graph().items()
        if a.startswith("tssac_core.")
        for b in targets
        if b.startswith("tssac_core.")
        and room_of(a) != room_of(b)
        and layer[room_of(b)] >= layer[room_of(a)]
        and (room_of(a), room_of(b)) not in MUTUAL
    )
    assert not offenders, offenders


@pytest.mark.parametrize(("room", "also_forbidden"), [("common", ()), ("wire", ("pymavlink", "numpy", "torch"))])
def test_the_bottom_rooms_import_nothing_of_the_project(room: str, also_forbidden: tuple[str, ...]):
    """``common`` (files, errors, stats) and ``wire`` (what the SITL and the bridge both speak) sit below every room:
    the wire is standard library only, so both ends import it and neither parses frames itself."""
    offenders = sorted(
        f"{module_name(p)} imports {m}"
        for p in (ROOT / "tssac_core" / room).rglob("*.py")
        for m in imports_of(p)
        if m.split(".")[0] in PACKAGES + also_forbidden
    )
    assert not offenders, offenders


def test_no_frame_is_parsed_outside_the_wire():
    """pymavlink's own parser (``parse_char``, ``parse_buffer``, ``decode``) is called nowhere: both ends split and
    decode datagrams with the wire's scanner and decoder."""
    offenders = sorted(
        f"{module_name(p)}: {call}"
        for pkg in PACKAGES
        for p in (ROOT / pkg).rglob("*.py")
        if not module_name(p).startswith("tssac_core.wire")
        for call in ("parse_char(", "parse_buffer(", ".decode(bytearray")
        if call in p.read_text()
    )
    assert not offenders, offenders


def test_ray_workers_import_this_checkout():
    """The Ray workers' PYTHONPATH starts with the directory that holds tssac_core (the checkout), wherever the module
    that computes it sits."""
    from tssac_core.parallel.ray_cluster import PROJECT_ROOT, worker_pythonpath

    assert PROJECT_ROOT == ROOT and (PROJECT_ROOT / "tssac_core" / "__init__.py").is_file()
    assert worker_pythonpath().split(os.pathsep)[0] == str(ROOT)
