"""docs/real_vehicles.md: every command on the page is one its program takes (parsed by the program's own argument
parser and configuration checks, nothing started), and the tests the page says fly them exist and fly those very
commands' options."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

from mavlink_bridge.companion import cli as companion_cli
from mavlink_bridge.fly.config import config_from_args as fly_config
from sim_vehicles import __main__ as sitl_cli

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "real_vehicles.md"


def page_commands() -> list[list[str]]:
    """The page's commands: its indented code lines."""
    return [shlex.split(line.strip()) for line in PAGE.read_text().splitlines() if re.match(r"^    \S", line)]


def test_every_command_on_the_page_is_taken_by_its_program() -> None:
    commands = page_commands()
    programs = [c[:3] if c[0] == "python" and c[1] == "-m" else c[:2] if c[0] == "python" else c[:1] for c in commands]
    assert [" ".join(p) for p in programs] == [
        "python -m sim_vehicles",
        "python -m mavlink_bridge.companion",
        "python -m mavlink_bridge.fly",
        "python benchmarks/bench_serial.py",
        "mavproxy.py",
    ]
    for argv in commands:
        if argv[:3] == ["python", "-m", "sim_vehicles"]:
            config = sitl_cli.config_from_args(sitl_cli.build_parser().parse_args(argv[3:]))
            assert config.serial_baud == 57600 and config.hold_start
        elif argv[:3] == ["python", "-m", "mavlink_bridge.companion"]:
            config = companion_cli.config_from_args(companion_cli.build_parser().parse_args(argv[3:]))
            budget = config.line_budget
            assert budget is not None and budget.baud == 57600 and budget.share < 0.25
        elif argv[:3] == ["python", "-m", "mavlink_bridge.fly"]:
            fly = fly_config(argv[3:])
            assert fly.serial_baud == 57600 and not fly.lockstep
        elif argv[:2] == ["python", "benchmarks/bench_serial.py"]:
            usage = subprocess.run(
                [sys.executable, str(ROOT / argv[1]), "--help"], capture_output=True, text=True, timeout=60, cwd=ROOT
            )
            assert usage.returncode == 0 and all(a in usage.stdout for a in argv[2:] if a.startswith("--"))
        else:  # MAVProxy on the world's output: the master string the routing test gives it
            assert argv[1].startswith("--master=udpin:127.0.0.1:")
            helper = (ROOT / "tests" / "ground_station_helpers.py").read_text()
            assert '"--master=' in helper


def test_the_tests_the_page_names_fly_its_options() -> None:
    text = PAGE.read_text()
    routing = (ROOT / "tests" / "test_routing.py").read_text()
    serial = (ROOT / "tests" / "test_serial_link.py").read_text()
    assert "test_mavproxy_watches_a_mission_the_companions_fly_over_serial" in text
    assert "def test_mavproxy_watches_a_mission_the_companions_fly_over_serial" in routing
    assert '"--serial", "57600", "--out"' in routing and '"--hold-start"' in routing
    assert '"--serial", "57600", "--speedup", "1"' in serial and '"--serial-byte-loss", "0.002"' in serial
