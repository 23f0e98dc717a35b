"""Two turn rates the monitor could start its lag from instead of the Kalman filter's, against the course rate a
JSBSim airframe flies: ATTITUDE's heading rate, and the lag model's own rate driven by the commands sent.

The lag model (issue 58, :mod:`tssac_core.assurance.lagged_backups`) turns the *course*: it was fitted on the
airframe's ground track. ATTITUDE gives the *nose's* heading rate exactly, by the Euler kinematics of its body rates,
psi' = (q sin roll + r cos roll) / cos pitch; the two differ by the sideslip's rate. The model itself, run from a
straight start on the very commands the airframe flew (its delay, and its roll-in and roll-out time constants at the
flight's speed, from the response file), gives a rate without any measurement, off by what a first-order lag misses
of the roll. This benchmark flies the airframe under its inner loop through random heading-rate commands (held
0.5-8 s, each within the turn-rate limit) at each tabled speed, and compares at the end of every world step the
nose's rate with the course rate there (the mean of the two steps' course rates around it), overall and in the
steadiest steps (roll rate under 0.5 deg/s), and the model's mean rate over each step with the course rate over it.

    python benchmarks/bench_nose_rate.py [--aircraft f16] [--trials 3] [--seed 1] [--json OUT]
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.output import add_json_option, write_figures  # noqa: E402
from sim_vehicles.dynamics.jsbsim_airframe import JsbsimAirframe, StartState, airframe_path, load_airframe  # noqa: E402
from tssac_core.assurance.lagged_backups import LagState, lagged_rollout  # noqa: E402
from tssac_core.assurance.monitor import Limits  # noqa: E402
from tssac_core.common.cli import command_description  # noqa: E402
from tssac_core.sim.airframe_response import AirframeResponse, airframe_lag, load_response  # noqa: E402

SPEEDS_M_S = (150.0, 200.0, 250.0, 300.0)
TURN_RATE_MAX_RAD_S = math.radians(5.0)
DT_S = 0.1
STEADY_ROLL_RATE_DEG_S = 0.5


def nose_rate_rad_s(roll: float, pitch: float, q: float, r: float) -> float:
    """The nose's heading rate, counter-clockwise positive (the project's frame), from ATTITUDE's body rates."""
    return -(q * math.sin(roll) + r * math.cos(roll)) / math.cos(pitch)


def fly(aircraft: str, speed_m_s: float, rng: np.random.Generator) -> np.ndarray:
    """One flight of 12 random commands after 3 s straight: per step, the nose's rate, the course rate over the step,
    the roll rate and the command (rad/s), (S, 4)."""
    spec = load_airframe(aircraft)
    commands = [(0.0, 30)] + [
        (float(rng.uniform(-1, 1)) * TURN_RATE_MAX_RAD_S, int(rng.integers(5, 80))) for _ in range(12)
    ]
    rows = []
    with JsbsimAirframe(spec, StartState(0.0, 0.0, 5000.0, speed_m_s, 0.0)) as airframe:
        for command, steps in commands:
            for _ in range(steps):
                s = airframe.step(command, 0.0, DT_S)
                nose = nose_rate_rad_s(s.roll_rad, s.pitch_rad, s.pitch_rate_rad_s, s.yaw_rate_rad_s)
                rows.append((nose, s.turn_rate_rad_s, s.roll_rate_rad_s, command))
    return np.array(rows)


def model_rates(response: AirframeResponse, speed_m_s: float, commands: np.ndarray) -> np.ndarray:
    """The lag model's mean heading rate over each step, from straight flight, under ``commands`` (rad/s, one a step):
    what the monitor would know of the rate from what it sent alone (the monitor's own rollout, its heading's change
    over each step)."""
    lag = airframe_lag(response, np.array([speed_m_s]), DT_S)
    speed = np.array([speed_m_s])
    lim = Limits(speed, speed, np.array([TURN_RATE_MAX_RAD_S]), np.array([10.0]))
    straight = LagState.steady(np.zeros(1), int(lag.delay_steps[0]))
    path = lagged_rollout(
        np.zeros(1), np.zeros(1), speed, np.zeros(1), straight, commands[None, :], np.zeros((1, len(commands))), lag,
        lim, DT_S,
    )  # fmt: skip
    return np.diff(path.headings[0], prepend=0.0) / DT_S


def figures(rows: np.ndarray, model: np.ndarray) -> dict[str, float]:
    """The nose's rate against the course rate at the end of each step (deg/s): largest, 99th percentile, median;
    overall and in the steady steps; and the lag model's rate over each step against the course rate over it."""
    course_at_end = 0.5 * (rows[:-1, 1] + rows[1:, 1])
    gap = np.degrees(np.abs(rows[:-1, 0] - course_at_end))
    steady = np.degrees(np.abs(rows[:-1, 2])) < STEADY_ROLL_RATE_DEG_S
    model_gap = np.degrees(np.abs(model - rows[:, 1]))
    return {
        "max_deg_s": float(gap.max()),
        "p99_deg_s": float(np.percentile(gap, 99)),
        "median_deg_s": float(np.median(gap)),
        "steady_share": float(steady.mean()),
        "steady_max_deg_s": float(gap[steady].max()),
        "steady_p99_deg_s": float(np.percentile(gap[steady], 99)),
        "model_max_deg_s": float(model_gap.max()),
        "model_p99_deg_s": float(np.percentile(model_gap, 99)),
        "model_median_deg_s": float(np.median(model_gap)),
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=command_description(__doc__))
    parser.add_argument("--aircraft", default="f16", help="a JSBSim airframe of sim_vehicles (default f16)")
    parser.add_argument("--trials", type=int, default=3, help="flights per speed (default 3)")
    parser.add_argument("--seed", type=int, default=1, help="the commands' seed (default 1)")
    parser.add_argument(
        "--response",
        type=Path,
        default=Path(__file__).resolve().parents[1] / "sim_vehicles" / "dynamics" / "airframes" / "f16.response.yaml",
        help="the airframe's fitted response, for the lag model (default: the f16's)",
    )
    add_json_option(parser, "nose_rate")
    args = parser.parse_args(argv)
    if args.trials < 1:
        parser.error("--trials must be >= 1")
    response = load_response(args.response, airframe_path(args.aircraft))
    rng = np.random.default_rng(args.seed)
    results = {"aircraft": args.aircraft, "response": args.response.name, "trials": args.trials, "seed": args.seed}
    results["speeds"] = {}
    for speed in SPEEDS_M_S:
        flights = [fly(args.aircraft, speed, rng) for _ in range(args.trials)]
        model = np.concatenate([model_rates(response, speed, f[:, 3]) for f in flights])
        row = figures(np.concatenate(flights), model)
        results["speeds"][f"{speed:g}"] = row
        print(
            f"{speed:5.0f} m/s: nose - course rate max {row['max_deg_s']:.2f} deg/s, p99 {row['p99_deg_s']:.2f}, "
            f"median {row['median_deg_s']:.3f}; roll rate < {STEADY_ROLL_RATE_DEG_S} deg/s ({row['steady_share']:.0%} "
            f"of steps): max {row['steady_max_deg_s']:.2f}, p99 {row['steady_p99_deg_s']:.2f}; lag model from the "
            f"commands - course rate max {row['model_max_deg_s']:.2f}, p99 {row['model_p99_deg_s']:.2f}, median "
            f"{row['model_median_deg_s']:.3f}"
        )
    if args.json is not None:
        write_figures(args.json, results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
