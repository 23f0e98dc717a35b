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


BRIDGE_ROOMS = ("link", "estimation", "processes", "companion", "fly")
"""``mavlink_bridge``'s rooms, lowest first: each imports only the rooms before it."""


def room_edges(package: str, rooms: tuple[str, ...]) -> set[tuple[str, str]]:
    """(room, room it imports) for every import between two rooms of ``package``."""
    graph = project_graph()
    return {
        (a.split(".")[1], b.split(".")[1])
        for a, targets in graph.items()
        if a.startswith(package + ".") and a.split(".")[1] in rooms
        for b in targets
        if b.startswith(package + ".") and b.split(".")[1] != a.split(".")[1]
    }


def test_the_bridge_is_in_rooms_with_no_upward_arrow():
    """Every module of ``mavlink_bridge`` lives in one of its rooms (no loose top-level module), and a room imports
    only the rooms below it: no upward arrow, so no circle between rooms."""
    loose = sorted(p.name for p in (ROOT / "mavlink_bridge").glob("*.py") if p.name != "__init__.py")
    assert not loose, loose
    rooms = sorted(p.name for p in (ROOT / "mavlink_bridge").iterdir() if (p / "__init__.py").is_file())
    assert rooms == sorted(BRIDGE_ROOMS)
    edges = room_edges("mavlink_bridge", BRIDGE_ROOMS)
    assert ("fly", "companion") in edges and ("companion", "link") in edges  # the walk sees the rooms' imports
    upward = sorted((a, b) for a, b in edges if BRIDGE_ROOMS.index(b) >= BRIDGE_ROOMS.index(a))
    assert not upward, upward


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
    it imports nothing from the project outside its own room, so each of them may import it."""
    offenders = sorted(
        f"{module_name(p)} imports {m}"
        for p in (ROOT / "tssac_core" / "assurance").rglob("*.py")
        for m in imports_of(p)
        if m.split(".")[0] in PACKAGES and not m.startswith("tssac_core.assurance.")
    )
    assert not offenders, offenders


ROOMS = (
    ("tssac_core.common", "tssac_core.assurance", "tssac_core.wire"),
    ("tssac_core.sim",),
    ("tssac_core.algos",),
    ("tssac_core.deploy", "tssac_core.parallel", "tssac_core.reporting"),
    ("tssac_core.train",),
    ("tssac_core.experiments", "tssac_core.evaluate"),
)
"""tssac_core's rooms (its subpackages, and its one top-level command), lowest first: a room imports only rooms of lower
layers. The experiments sit above training: ``train --seeds`` and the grid run their jobs on the same executors
(tssac_core.train.jobs), and no room imports one of its own layer."""


def room_of(module: str) -> str:
    return ".".join(module.split(".")[:2])


def test_every_module_has_a_room():
    """At tssac_core's top level only the package face and the one command that is a module (``python -m
    tssac_core.evaluate``): the rest lives in a subpackage that names what it is (the commands' shared runner, too, is
    ``common.cli``)."""
    loose = sorted(p.name for p in (ROOT / "tssac_core").glob("*.py"))
    assert loose == ["__init__.py", "evaluate.py"], loose
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
        if b.startswith("tssac_core.") and room_of(a) != room_of(b) and layer[room_of(b)] >= layer[room_of(a)]
    )
    assert not offenders, offenders


@pytest.mark.parametrize(("room", "also_forbidden"), [("common", ()), ("wire", ("pymavlink", "numpy", "torch"))])
def test_the_bottom_rooms_import_nothing_of_the_project(room: str, also_forbidden: tuple[str, ...]):
    """``common`` (files, errors, cli, stats) and ``wire`` (what the SITL and the bridge both speak) sit below every
    room: they import nothing of the project outside their own room, and the wire is standard library only, so both
    ends import it and neither parses frames itself."""
    offenders = sorted(
        f"{module_name(p)} imports {m}"
        for p in (ROOT / "tssac_core" / room).rglob("*.py")
        for m in imports_of(p)
        if m.split(".")[0] in PACKAGES + also_forbidden and not m.startswith(f"tssac_core.{room}.")
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


WIRE_FIELD_MODULES = (
    "mavlink_bridge/link/frames.py",
    "mavlink_bridge/link/connection.py",
    "sim_vehicles/autopilot/clock.py",
    "sim_vehicles/protocol/commands.py",
    "sim_vehicles/autopilot/setpoints.py",
    "sim_vehicles/protocol/streams.py",
    "sim_vehicles/autopilot/telemetry.py",
    "sim_vehicles/autopilot/vehicle.py",
    "sim_vehicles/protocol/vehicle_link.py",
)
"""The modules that write or read MAVLink fields, on either end."""
WIRE_FLOAT_SCALES = frozenset({100.0, 1000.0, 1e6, 1e7, 1e9, 1e-7})
"""The scales of :mod:`tssac_core.wire.units` (cm, ms and mm, us, degE7, ns, degE7 back) as float literals."""
WIRE_INT_SCALES = frozenset({100, 1000, 1_000_000, 10_000_000})
"""The same as integers, counted where they multiply or divide (``HDOP_X100 = 100`` is a value, not a scale)."""


def scale_literals(path: Path) -> list[str]:
    """Where ``path`` spells one of the wire's scales itself."""
    tree = ast.parse(path.read_text())
    scaled = {
        id(side)
        for node in ast.walk(tree)
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Mult, ast.Div, ast.FloorDiv))
        for side in (node.left, node.right)
    }
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Constant):
            continue
        value = node.value
        if (type(value) is float and value in WIRE_FLOAT_SCALES) or (
            type(value) is int and value in WIRE_INT_SCALES and id(node) in scaled
        ):
            found.append(f"{path.name}:{node.lineno}: {value!r}")
    return sorted(found)


def test_units_are_converted_only_in_the_wire():
    """Both ends take MAVLink's scales (ms, us, mm, cm/s, degE7, ns) from ``tssac_core.wire.units``: a field module
    that spells one has re-written a conversion the other end reads back with the wire's function."""
    offenders = sorted(line for module in WIRE_FIELD_MODULES for line in scale_literals(ROOT / module))
    assert not offenders, offenders


def test_the_scale_finder_finds_a_scale(tmp_path: Path):
    sample = tmp_path / "sample.py"
    sample.write_text(
        "HDOP_X100 = 100\nt_ms = int(round(t_s * 1000.0))\nus = ms * 1000\nif n in (1, 100, 1000): pass\n"
    )
    assert scale_literals(sample) == ["sample.py:2: 1000.0", "sample.py:3: 1000"]


def test_no_wire_conversion_is_defined_twice():
    """The functions of ``tssac_core.wire.units`` and ``geodetic`` are defined there only."""
    wire = {
        node.name
        for name in ("units", "geodetic")
        for node in ast.walk(ast.parse((ROOT / "tssac_core" / "wire" / f"{name}.py").read_text()))
        if isinstance(node, ast.FunctionDef) and not node.name.startswith("_")
    }
    assert {"ms_from_s", "world_from_ned", "yaw_rate_from_omega", "deg_e7", "local_to_geodetic"} <= wire
    offenders = sorted(
        f"{module_name(p)} defines {node.name}"
        for pkg in PACKAGES
        for p in (ROOT / pkg).rglob("*.py")
        if not module_name(p).startswith("tssac_core.wire")
        for node in ast.walk(ast.parse(p.read_text()))
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name in wire
    )
    assert not offenders, offenders


def test_both_ends_convert_through_the_wire(monkeypatch: pytest.MonkeyPatch):
    """A setpoint from the companion to the SITL and a fix from the SITL to the companion: each end calls the wire's
    conversions (recorded), and the round trips give back what went in."""
    import math

    import numpy as np
    from pymavlink.dialects.v20 import ardupilotmega as mavlink2

    from mavlink_bridge.link.frames import action_to_setpoint, from_global_position_int, from_local_position_ned
    from sim_vehicles.autopilot import setpoints, telemetry
    from sim_vehicles.autopilot.clock import Clock
    from sim_vehicles.autopilot.events import WorldFlags
    from sim_vehicles.autopilot.modes import FlightMode
    from sim_vehicles.autopilot.vehicle import Vehicle, VehicleSetup
    from sim_vehicles.link.link_model import GpsFix
    from tssac_core.sim.scenario import Role, load
    from tssac_core.wire import units

    calls: list[str] = []

    def recording(name: str):  # noqa: ANN202
        original = getattr(units, name)

        def wrapper(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
            calls.append(name)
            return original(*args, **kwargs)

        return wrapper

    for name, value in list(vars(units).items()):
        if callable(value) and getattr(value, "__module__", None) == units.__name__:
            monkeypatch.setattr(units, name, recording(name))

    def took(*names: str) -> bool:
        seen = set(calls)
        calls.clear()
        return set(names) <= seen

    scen = load(ROOT / "scenarios" / "strike.yaml")
    spec = scen.vehicle(Role.DECOY)
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)

    # The companion scales an action into a setpoint; the SITL parses it and flies it back into an action.
    setpoint = action_to_setpoint((0.5, -0.25), spec)
    assert took("command_from_action", "yaw_rate_from_omega")
    setup = VehicleSetup(
        index=0,
        role="decoy",
        sysid=1,
        turn_rate_max_rad_s=math.radians(spec.turn_rate_max_deg_s),
        accel_max_m_s2=spec.accel_max_m_s2,
        speed_min_m_s=spec.speed_min_m_s,
        speed_max_m_s=spec.speed_max_m_s,
        dt_s=scen.dt_s,
        origin=scen.origin,
        home_east_m=0.0,
        home_north_m=0.0,
        link=scen.link,
        setpoint_timeout_s=1.0,
    )
    vehicle = Vehicle(setup, Clock(), WorldFlags(), np.random.default_rng(0))
    vehicle.set_armed(True)
    vehicle.set_mode(FlightMode.GUIDED)
    msg = mav.set_position_target_local_ned_encode(
        0, 1, 1, 12, 1087, 0, 0, 0, 0, 0, 0, setpoint.accel_m_s2, 0, 0, 0, setpoint.yaw_rate_rad_s
    )
    demand = setpoints.parse_position_target(msg)
    assert isinstance(demand, setpoints.Demand) and vehicle.fly_demand(demand)
    calls.clear()
    assert vehicle.action() == pytest.approx((0.5, -0.25))
    assert took("omega_from_yaw_rate", "action_from_command")

    # The SITL writes a fix as LOCAL_POSITION_NED and GLOBAL_POSITION_INT; the companion reads it back.
    fix = GpsFix(time_s=12.3, east_m=40_000.0, north_m=25_000.0, vel_east_m_s=-120.0, vel_north_m_s=200.0)
    local = mav.local_position_ned_encode(*telemetry.local_position_ned_fields(fix))
    truth = telemetry.VehicleTruth(0.0, 0.0, 200.0, 1.0, 0.05, 0.0)
    glob = telemetry.global_position_int(mav, scen.origin, fix, truth)
    att = telemetry.attitude(mav, truth, 0)
    assert took("ned_from_world", "ms_from_s", "cm_from_m", "mm_from_m", "deg_e7", "yaw_rate_from_omega")
    assert att.yawspeed == pytest.approx(-0.05)
    m = from_local_position_ned(local.time_boot_ms, local.x, local.y, local.vx, local.vy)
    g = from_global_position_int(scen.origin, glob.time_boot_ms, glob.lat, glob.lon, glob.vx, glob.vy)
    assert took("world_from_ned", "s_from_ms", "m_from_cm", "deg_from_e7")
    for got in (m, g):
        assert got.t_s == pytest.approx(12.3)
        assert (got.east_m, got.north_m) == pytest.approx((40_000.0, 25_000.0), abs=0.02)
        assert (got.vel_east_m_s, got.vel_north_m_s) == pytest.approx((-120.0, 200.0), abs=0.01)


MAX_FUNCTION_LINES = 80
"""Issue 60: no function of the three packages is longer; an exception says why on its ``def`` line (``# long:``)."""


def long_functions(source: str) -> list[tuple[str, int]]:
    """The functions of ``source`` over MAX_FUNCTION_LINES lines (decorators not counted) without a ``# long:`` reason
    on their ``def`` line: (name, lines)."""
    lines = source.splitlines()
    return [
        (node.name, node.end_lineno - node.lineno + 1)
        for node in ast.walk(ast.parse(source))
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
        and node.end_lineno is not None
        and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES
        and "# long:" not in lines[node.lineno - 1]
    ]


def test_no_function_is_longer_than_80_lines():
    offenders = sorted(
        f"{module_name(p)}.{name}: {n} lines"
        for package in PACKAGES
        for p in (ROOT / package).rglob("*.py")
        for name, n in long_functions(p.read_text(encoding="utf-8"))
    )
    assert not offenders, offenders


def test_the_length_rule_sees_a_long_function_and_its_reason():
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_FUNCTION_LINES))
    assert long_functions(f"def f():\n{body}") == [("f", MAX_FUNCTION_LINES + 1)]
    assert long_functions(f"def f():  # long: a table\n{body}") == []
    assert long_functions(f"def f():\n{body[: -len(body.splitlines()[-1]) - 1]}") == []


SITL_ROOMS = ("link", "autopilot", "clock", "dynamics", "protocol")
"""``sim_vehicles``' rooms, lowest first: each imports only the rooms before it; the run (world_runner, truth_log, the
commands from flags and from a configuration) sits above them all (its configuration is tssac_core.sim.sitl_config)."""
SITL_RUN = ["__init__.py", "__main__.py", "from_config.py", "truth_log.py", "world_runner.py"]


def test_the_sitl_is_in_rooms_with_no_upward_arrow():
    loose = sorted(p.name for p in (ROOT / "sim_vehicles").glob("*.py"))
    assert loose == SITL_RUN, loose
    rooms = sorted(p.name for p in (ROOT / "sim_vehicles").iterdir() if (p / "__init__.py").is_file())
    assert rooms == sorted(SITL_ROOMS)
    edges = room_edges("sim_vehicles", SITL_ROOMS)
    assert ("protocol", "autopilot") in edges and ("autopilot", "link") in edges  # the walk sees the rooms' imports
    upward = sorted((a, b) for a, b in edges if b not in SITL_ROOMS or SITL_ROOMS.index(b) >= SITL_ROOMS.index(a))
    assert not upward, upward
