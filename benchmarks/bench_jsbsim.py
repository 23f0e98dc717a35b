"""Measure the JSBSim airframe (sim_vehicles/dynamics/jsbsim_airframe.py): what one SITL mission pays for it.

Figures: CPU seconds to create, trim and settle one airframe; CPU milliseconds per 0.1 s world step for three
airframes flying turns and speed changes (the target is at most 2 ms: 50x real time for the team); the same with
the bare JSBSim runs alone (the floor the inner loop adds to); real-time factor; the achievable acceleration and
deceleration from 150-300 m/s (the airframe file's limits). CPU time on a shared machine
still varies with the load (twofold here): each figure is the minimum and the median over interleaved rounds.

    python benchmarks/bench_jsbsim.py [--airframe f16] [--steps 400] [--repeats 8] [--creations 5] \
        [--json /tmp/bench_jsbsim.json]
"""

from __future__ import annotations

import argparse
import logging
import math
import statistics
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.output import add_json_option, write_figures  # noqa: E402
from sim_vehicles.dynamics.jsbsim_airframe import (  # noqa: E402
    AirframeSpec,
    JsbsimAirframe,
    StartState,
    Wind,
    load_airframe,
)
from tssac_core.common.cli import command_description  # noqa: E402

_log = logging.getLogger("bench_jsbsim")

DT_S = 0.1
VEHICLES = 3
TARGET_MS_PER_STEP = 2.0
LIMIT_SPEEDS_M_S = (150.0, 200.0, 250.0, 300.0)


@dataclass(frozen=True)
class JsbsimBench:
    """One run's figures (CPU time of this process; the machine may be shared, so each figure is the minimum and
    the median over ``repeats`` interleaved rounds)."""

    airframe: str
    physics_rate_hz: float
    autopilot_every: int
    settle_s: float
    creations: int
    create_cpu_s_min: float
    """CPU seconds to create, trim and settle one airframe (fastest)."""
    create_cpu_s_median: float
    steps: int
    """World steps flown per airframe, over all rounds."""
    repeats: int
    ms_per_step_3_min: float
    """CPU milliseconds per 0.1 s world step for three airframes, inner loop and position included."""
    ms_per_step_3_median: float
    bare_ms_per_step_3_min: float
    """The same for JSBSim's own runs alone (12 per airframe per step, no inner loop, level flight)."""
    bare_ms_per_step_3_median: float
    realtime_factor_3_median: float
    """Simulated seconds per CPU second for the team of three (median round)."""
    target_ms_per_step_3: float
    meets_target: bool
    """The median round is within the target."""
    limit_speeds_m_s: list[float]
    """Start speeds of the achievable-acceleration flights (level, 5,000 m)."""
    max_accel_m_s2: list[float]
    """Mean acceleration over 15 s at full throttle from each speed."""
    max_decel_m_s2: list[float]
    """Mean acceleration over 15 s at no throttle from each speed (negative)."""


def starts() -> list[StartState]:
    """Three vehicles as the scenarios start them: 5 km apart, 250 m/s, 5,000 m, different headings."""
    return [
        StartState(east_m=5000.0 * i, north_m=0.0, alt_m=5000.0, speed_m_s=250.0, heading_rad=0.5 * i)
        for i in range(VEHICLES)
    ]


def command(k: int, i: int) -> tuple[float, float]:
    """Vehicle i's setpoints at step k: turns both ways at up to 5 deg/s and +-3 m/s^2, changing every 10 s."""
    phase = (k // 100 + i) % 4
    turn_rad_s = math.radians(5.0) * (1.0, -1.0, 0.5, 0.0)[phase]
    accel_m_s2 = (3.0, 0.0, -3.0, 0.0)[phase]
    return turn_rad_s, accel_m_s2


def measure_creation(spec: AirframeSpec, creations: int) -> list[float]:
    """CPU seconds of each airframe's creation (load, trim, settle)."""
    seconds = []
    for n in range(creations):
        begin = time.process_time()
        airframe = JsbsimAirframe(spec, starts()[n % VEHICLES], Wind(), 150.0, 300.0)
        seconds.append(time.process_time() - begin)
        airframe.close()
    return seconds


def measure_steps(spec: AirframeSpec, steps: int, repeats: int) -> tuple[list[float], list[float]]:
    """CPU ms per world step for three airframes in each round: flying the commands with the inner loop, and
    JSBSim's bare runs on three other airframes in level flight (the floor the inner loop adds to)."""
    flying = [JsbsimAirframe(spec, s, Wind(), 150.0, 300.0) for s in starts()]
    floor = [JsbsimAirframe(spec, s, Wind(), 150.0, 300.0) for s in starts()]
    runs = [a.fdm.run for a in floor]
    substeps = round(DT_S * spec.physics_rate_hz)
    per_round = max(1, steps // repeats)
    flown_ms, bare_ms = [], []
    k = 0
    for _ in range(repeats):
        begin = time.process_time()
        for _ in range(per_round):
            for i, airframe in enumerate(flying):
                airframe.step(*command(k, i), DT_S)
            k += 1
        flown_ms.append((time.process_time() - begin) * 1000.0 / per_round)
        begin = time.process_time()
        for _ in range(per_round):
            for run in runs:
                for _ in range(substeps):
                    run()
        bare_ms.append((time.process_time() - begin) * 1000.0 / per_round)
    for airframe in flying + floor:
        airframe.close()
    return flown_ms, bare_ms


def mean_accel(spec: AirframeSpec, speed_m_s: float, accel_cmd_m_s2: float, duration_s: float = 15.0) -> float:
    """Mean airspeed change per second over ``duration_s`` of level flight commanding far more than the
    airframe can do (full or no throttle)."""
    start = StartState(east_m=0.0, north_m=0.0, alt_m=5000.0, speed_m_s=speed_m_s, heading_rad=0.0)
    with JsbsimAirframe(spec, start, Wind(), 50.0, 500.0) as airframe:
        before = airframe.state.airspeed_m_s
        for _ in range(round(duration_s / DT_S)):
            after = airframe.step(0.0, accel_cmd_m_s2, DT_S).airspeed_m_s
    return (after - before) / duration_s


def bench(airframe: str, steps: int, repeats: int, creations: int) -> JsbsimBench:
    spec = load_airframe(airframe)
    create_s = measure_creation(spec, creations)
    flown_ms, bare_ms = measure_steps(spec, steps, repeats)
    return JsbsimBench(
        airframe=spec.name,
        physics_rate_hz=spec.physics_rate_hz,
        autopilot_every=spec.autopilot_every,
        settle_s=spec.settle_s,
        creations=creations,
        create_cpu_s_min=min(create_s),
        create_cpu_s_median=statistics.median(create_s),
        steps=max(1, steps // repeats) * repeats,
        repeats=repeats,
        ms_per_step_3_min=min(flown_ms),
        ms_per_step_3_median=statistics.median(flown_ms),
        bare_ms_per_step_3_min=min(bare_ms),
        bare_ms_per_step_3_median=statistics.median(bare_ms),
        realtime_factor_3_median=DT_S * 1000.0 / statistics.median(flown_ms),
        target_ms_per_step_3=TARGET_MS_PER_STEP,
        meets_target=statistics.median(flown_ms) <= TARGET_MS_PER_STEP,
        limit_speeds_m_s=list(LIMIT_SPEEDS_M_S),
        max_accel_m_s2=[mean_accel(spec, v, 50.0) for v in LIMIT_SPEEDS_M_S],
        max_decel_m_s2=[mean_accel(spec, v, -50.0) for v in LIMIT_SPEEDS_M_S],
    )


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=command_description(__doc__))
    parser.add_argument("--airframe", default="f16", help="bundled airframe name or YAML path")
    parser.add_argument("--steps", type=int, default=400, help="world steps of 0.1 s per airframe (default 400)")
    parser.add_argument("--repeats", type=int, default=8, help="rounds the steps are split into (default 8)")
    parser.add_argument("--creations", type=int, default=5, help="airframes created for the creation figure")
    add_json_option(parser, "jsbsim")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    result = bench(args.airframe, args.steps, args.repeats, args.creations)
    _log.info(
        "%s: create+trim+settle %.3f s CPU per airframe (median; min %.3f s)\n"
        "3 airframes x 0.1 s: %.2f ms CPU per step (median; min %.2f ms), %.0fx real time; "
        "bare JSBSim %.2f ms (median; min %.2f ms); target <= %.1f ms: %s",
        result.airframe,
        result.create_cpu_s_median,
        result.create_cpu_s_min,
        result.ms_per_step_3_median,
        result.ms_per_step_3_min,
        result.realtime_factor_3_median,
        result.bare_ms_per_step_3_median,
        result.bare_ms_per_step_3_min,
        result.target_ms_per_step_3,
        "met" if result.meets_target else "MISSED",
    )
    for speed, accel, decel in zip(result.limit_speeds_m_s, result.max_accel_m_s2, result.max_decel_m_s2):
        _log.info("from %.0f m/s: %+.2f m/s^2 at full throttle, %+.2f at none (15 s means)", speed, accel, decel)
    write_figures(args.json, asdict(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
