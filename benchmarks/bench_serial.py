"""Measure the companion's telemetry over a serial line: bytes a second each way against what the line carries.

Flies ``scenarios/short.yaml`` (about 12 s) with ``python -m mavlink_bridge.fly --serial BAUD`` in real time (the
world puts each vehicle on a pseudo-terminal at BAUD, throttled to it, and the companions fly over them), signed as
fly signs by default, and reports per companion: the bytes a second it received from the vehicle and sent to it
(its link counters over its flight's wall time), the share of the line (BAUD / 10 bytes/s each way), and what was
lost (frames missing from the vehicle's sequence numbers, garbage, bad CRCs, frames the vehicle's transmit buffer
could not hold). Beside the measurement, the computed need of the streams the companion asks for
(:mod:`mavlink_bridge.link.telemetry_budget`, frames at their longest) and the margin: line / need.

    python benchmarks/bench_serial.py [--baud 57600] [--setpoints body-rates] [--json benchmarks/results/serial.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from mavlink_bridge.link.guided_commands import SetpointDialect  # noqa: E402
from mavlink_bridge.link.telemetry_budget import companion_streams, line_budget  # noqa: E402
from tssac_core.sim.scenario import load  # noqa: E402
from tssac_core.wire.uart import bytes_per_s  # noqa: E402

SCENARIO = REPO / "scenarios" / "short.yaml"
ROLES = ("decoy", "detect", "strike")


def fly(baud: int, setpoints: str, work: Path) -> dict[str, Any]:
    """One real-time mission over serial lines at ``baud``: the companions' statuses and the lines' counters."""
    argv = [sys.executable, "-m", "mavlink_bridge.fly", "--scenario", str(SCENARIO), "--pilot", "straight"]
    argv += ["--serial", str(baud), "--speedup", "1", "--setpoints", setpoints, "--no-progress"]
    argv += ["--json", str(work / "fly.json"), "--logs", str(work / "logs")]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=300, cwd=REPO)
    if proc.returncode != 0:
        raise SystemExit(f"fly failed ({proc.returncode}): {proc.stderr.strip().splitlines()[-1:]}")
    mdir = work / "logs" / "mission-000"
    mission = json.loads((work / "fly.json").read_text())["missions"][0]
    statuses = {r: json.loads((mdir / f"{r}.status.json").read_text()) for r in ROLES}
    summary = json.loads((mdir / "truth.jsonl").read_text().splitlines()[-1])
    return {"mission": mission, "statuses": statuses, "serial": {r: summary["counters"][r]["serial"] for r in ROLES}}


def measure(baud: int, setpoints: str) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="bench-serial-") as tmp:
        run = fly(baud, setpoints, Path(tmp))
    line = bytes_per_s(baud)
    scenario = load(SCENARIO)
    need = line_budget(baud, companion_streams(scenario.dt_s, False, SetpointDialect(setpoints)), signed=True)
    roles = {}
    for role in ROLES:
        status, serial = run["statuses"][role], run["serial"][role]
        wall = float(status["flight_wall_s"])
        link = status["link"]
        rx, tx = link["bytes_rx"] / wall, link["bytes_tx"] / wall
        roles[role] = {
            "status": status["status"],
            "flight_wall_s": round(wall, 2),
            "from_vehicle_bytes_per_s": round(rx, 1),
            "to_vehicle_bytes_per_s": round(tx, 1),
            "share_of_line": round(max(rx, tx) / line, 3),
            "frames_lost_rx": link["frames_lost_rx"],
            "garbage_bytes_rx": link["garbage_bytes_rx"],
            "bad_data_rx": link["bad_data_rx"],
            "tx_overflow_frames": serial["tx_overflow_frames"],
            "companion_frames_bad_crc_at_vehicle": serial["from_companion"]["bad_crc"],
        }
    return {
        "baud": baud,
        "setpoints": setpoints,
        "line_bytes_per_s": line,
        "success": run["mission"]["success"],
        "sim_time_s": run["mission"]["sim_time_s"],
        "computed_need": {
            "from_vehicle_bytes_per_s": round(need.from_vehicle_bytes_per_s, 1),
            "to_vehicle_bytes_per_s": round(need.to_vehicle_bytes_per_s, 1),
            "share_of_line": round(need.share, 3),
            "margin_x": round(1.0 / need.share, 1),
        },
        "measured_margin_x": round(1.0 / max(r["share_of_line"] for r in roles.values()), 1),
        "roles": roles,
    }


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--baud", type=int, action="append", help="baud rate(s) to fly at (default 57600 and 921600)")
    p.add_argument("--setpoints", choices=[d.value for d in SetpointDialect], default=SetpointDialect.BODY_RATES.value)
    p.add_argument("--json", type=Path, default=REPO / "benchmarks" / "results" / "serial.json")
    a = p.parse_args(argv)
    results = [measure(baud, a.setpoints) for baud in (a.baud or [57600, 921600])]
    for r in results:
        need = r["computed_need"]
        print(
            f"{r['baud']} baud ({r['line_bytes_per_s']:.0f} bytes/s each way), {r['setpoints']}: "
            f"success={r['success']}; computed need {need['from_vehicle_bytes_per_s']:.0f} in / "
            f"{need['to_vehicle_bytes_per_s']:.0f} out ({100 * need['share_of_line']:.0f}%, "
            f"margin {need['margin_x']}x); measured margin {r['measured_margin_x']}x"
        )
        for role, m in r["roles"].items():
            print(
                f"  {role}: {m['from_vehicle_bytes_per_s']:.0f} bytes/s in, {m['to_vehicle_bytes_per_s']:.0f} out "
                f"({100 * m['share_of_line']:.1f}% of the line); lost frames {m['frames_lost_rx']}, garbage "
                f"{m['garbage_bytes_rx']}, overflow {m['tx_overflow_frames']}"
            )
    a.json.parent.mkdir(parents=True, exist_ok=True)
    a.json.write_text(json.dumps({"machine": platform.node(), "runs": results}, indent=2) + "\n")
    print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
