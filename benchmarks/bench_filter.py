"""Measure mavlink_bridge.estimation.state_filter's models on noisy simulated tracks (seeded).

Figures per model: RMS position / speed / heading / turn-rate error after convergence, the raw
measurement's RMS position error, the position error at the end of a 2 s measurement gap (the
filter predicting through it) with the filter's own position_sigma_m there, and the time per
update and per predict_to call (us).

    python benchmarks/bench_filter.py [--runs 20] [--seed 0] \
        [--json benchmarks/results/filter.json]
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.output import add_json_option, write_figures  # noqa: E402
from mavlink_bridge.estimation.state_filter import FilterModel, FilterNoise, VehicleStateFilter  # noqa: E402
from tssac_core.common.cli import command_description

_log = logging.getLogger("bench_filter")

RATE_HZ = 10.0
DURATION_S = 60.0
SETTLE_S = 10.0
GAP_START_S = 40.0
GAP_S = 2.0
POS_SIGMA_M = 10.0
VEL_SIGMA_M_S = 1.0
MAX_ACCEL_M_S2 = 10.0
MAX_TURN_RATE_RAD_S = math.radians(5.0)


@dataclass(frozen=True)
class Track:
    """True state sampled at the measurement times."""

    t_s: np.ndarray
    pos_m: np.ndarray  # (n, 2) east, north
    vel_m_s: np.ndarray  # (n, 2)
    turn_rate_rad_s: np.ndarray  # (n,)


def simulate(
    turn_rate_fn: Callable[[float], float],
    accel_fn: Callable[[float], float],
    speed0_m_s: float,
    heading0_rad: float,
    substep_s: float = 0.01,
) -> Track:
    """Integrate eq. 5 with exact constant-turn sub-steps; sample at RATE_HZ."""
    n = int(round(DURATION_S * RATE_HZ)) + 1
    per_sample = int(round(1.0 / (RATE_HZ * substep_s)))
    x = y = 0.0
    v, phi = speed0_m_s, heading0_rad
    ts, ps, vs, ws = [], [], [], []
    t = 0.0
    for i in range(n):
        t = i / RATE_HZ
        ts.append(t)
        ps.append((x, y))
        vs.append((v * math.cos(phi), v * math.sin(phi)))
        ws.append(turn_rate_fn(t))
        for k in range(per_sample):
            tk = t + k * substep_s
            w, u = turn_rate_fn(tk), accel_fn(tk)
            v_mid = v + 0.5 * u * substep_s
            if abs(w) > 1e-9:
                x += v_mid / w * (math.sin(phi + w * substep_s) - math.sin(phi))
                y += v_mid / w * (math.cos(phi) - math.cos(phi + w * substep_s))
            else:
                x += v_mid * substep_s * math.cos(phi)
                y += v_mid * substep_s * math.sin(phi)
            phi += w * substep_s
            v += u * substep_s
    return Track(np.array(ts), np.array(ps), np.array(vs), np.array(ws))


def constant_turn_track() -> Track:
    """250 m/s, 3 deg/s left turn (the brief's reference case)."""
    return simulate(lambda t: math.radians(3.0), lambda t: 0.0, 250.0, 0.3)


def manoeuvring_track() -> Track:
    """Straight, then +5 / -5 deg/s turns, speed changes of +/-10 m/s^2; the gap spans a turn onset."""

    def turn(t: float) -> float:
        if 10.0 <= t < 25.0:
            return math.radians(5.0)
        if 25.0 <= t < 41.0:
            return math.radians(-4.0)
        if t >= 41.0:
            return math.radians(2.0)
        return 0.0

    def accel(t: float) -> float:
        if 15.0 <= t < 20.0:
            return 10.0
        if 30.0 <= t < 35.0:
            return -10.0
        return 0.0

    return simulate(turn, accel, 200.0, -1.0)


def _angle_err(a: float, b: float) -> float:
    return (a - b + math.pi) % (2.0 * math.pi) - math.pi


def run_once(track: Track, noise: FilterNoise, model: FilterModel, rng: np.random.Generator) -> dict[str, float]:
    """Filter one noisy copy of `track`; return error figures and call timings."""
    n = len(track.t_s)
    z_pos = track.pos_m + rng.normal(0.0, POS_SIGMA_M, size=(n, 2))
    z_vel = track.vel_m_s + rng.normal(0.0, VEL_SIGMA_M_S, size=(n, 2))
    f = VehicleStateFilter(noise, model)
    f.reset(track.t_s[0], z_pos[0], z_vel[0])
    pos_e2, raw_e2, spd_e2, hdg_e2, w_e2, sig = [], [], [], [], [], []
    gap_err = gap_sigma = math.nan
    upd_ns = pred_ns = 0
    n_upd = n_pred = 0
    for i in range(1, n):
        t = float(track.t_s[i])
        in_gap = GAP_START_S < t < GAP_START_S + GAP_S - 1e-9
        t0 = time.perf_counter_ns()
        f.predict_to(t)  # the companion predicts to each control step
        pred_ns += time.perf_counter_ns() - t0
        n_pred += 1
        if abs(t - (GAP_START_S + GAP_S)) < 1e-9:
            gap_err = float(np.hypot(*(np.array(f.pos_m) - track.pos_m[i])))
            gap_sigma = f.position_sigma_m
        if in_gap:
            continue
        t0 = time.perf_counter_ns()
        f.update(t, z_pos[i], z_vel[i])
        upd_ns += time.perf_counter_ns() - t0
        n_upd += 1
        if t >= SETTLE_S and not (GAP_START_S < t < GAP_START_S + GAP_S + 5.0):
            pos_e2.append(float(np.sum((np.array(f.pos_m) - track.pos_m[i]) ** 2)))
            raw_e2.append(float(np.sum((z_pos[i] - track.pos_m[i]) ** 2)))
            spd_e2.append((f.speed_m_s - float(np.hypot(*track.vel_m_s[i]))) ** 2)
            true_hdg = math.atan2(track.vel_m_s[i, 1], track.vel_m_s[i, 0])
            hdg_e2.append(_angle_err(f.heading_rad, true_hdg) ** 2)
            w = f.turn_rate_rad_s
            if w is not None:
                w_e2.append((w - float(track.turn_rate_rad_s[i])) ** 2)
            sig.append(f.position_sigma_m)
    return {
        "pos_rms_m": math.sqrt(np.mean(pos_e2)),
        "raw_pos_rms_m": math.sqrt(np.mean(raw_e2)),
        "speed_rms_m_s": math.sqrt(np.mean(spd_e2)),
        "heading_rms_deg": math.degrees(math.sqrt(np.mean(hdg_e2))),
        "turn_rate_rms_deg_s": math.degrees(math.sqrt(np.mean(w_e2))) if w_e2 else math.nan,
        "position_sigma_m": float(np.mean(sig)),
        "gap_end_pos_err_m": gap_err,
        "gap_end_position_sigma_m": gap_sigma,
        "update_us": upd_ns / n_upd / 1e3,
        "predict_us": pred_ns / n_pred / 1e3,
    }


def evaluate(track: Track, noise: FilterNoise, model: FilterModel, runs: int, seed: int) -> dict[str, float | None]:
    """Average figures over `runs` seeded noise draws (gap error: mean and max)."""
    rows = [run_once(track, noise, model, np.random.default_rng(seed + r)) for r in range(runs)]
    out: dict[str, float] = {}
    for key in rows[0]:
        vals = np.array([row[key] for row in rows])
        if key.endswith("_rms_m") or key.endswith("_rms_m_s") or key.endswith("_deg") or key.endswith("_deg_s"):
            out[key] = float(np.sqrt(np.mean(vals**2)))  # RMS over runs of per-run RMS
        else:
            out[key] = float(np.mean(vals))
    out["gap_end_pos_err_max_m"] = float(np.max([row["gap_end_pos_err_m"] for row in rows]))
    # NaN (no turn rate in the constant-velocity model) is not JSON: report None.
    return {k: (None if math.isnan(v) else round(v, 3)) for k, v in out.items()}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=command_description(__doc__))
    parser.add_argument("--runs", type=int, default=20, help="noise draws per case (default 20)")
    parser.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    add_json_option(parser, "filter")
    args = parser.parse_args(argv)
    if args.runs < 1:
        parser.error("--runs must be >= 1")
    logging.basicConfig(level=logging.INFO, format="%(message)s")

    base = FilterNoise.from_sensor(POS_SIGMA_M, VEL_SIGMA_M_S, MAX_ACCEL_M_S2, MAX_TURN_RATE_RAD_S)
    cases: list[tuple[str, FilterModel, FilterNoise]] = [
        ("constant_turn", FilterModel.CONSTANT_TURN, base),
        ("constant_turn_ekf", FilterModel.CONSTANT_TURN_EKF, base),
        ("constant_velocity", FilterModel.CONSTANT_VELOCITY, base),
    ]
    # Give the constant-velocity model its best shot: its acceleration noise must cover turns.
    for accel in (5.0, 10.0, 20.0, 40.0):
        cases.append(
            (
                f"constant_velocity_accel{accel:g}",
                FilterModel.CONSTANT_VELOCITY,
                FilterNoise(POS_SIGMA_M, VEL_SIGMA_M_S, accel_sigma_m_s2=accel),
            )
        )
    tracks = {"constant_turn_250ms_3degs": constant_turn_track(), "manoeuvring": manoeuvring_track()}
    track_results: dict[str, dict[str, dict[str, float | None]]] = {}
    results: dict[str, object] = {
        "settings": {
            "runs": args.runs,
            "seed": args.seed,
            "rate_hz": RATE_HZ,
            "duration_s": DURATION_S,
            "settle_s": SETTLE_S,
            "gap_s": GAP_S,
            "gap_start_s": GAP_START_S,
            "pos_sigma_m": POS_SIGMA_M,
            "vel_sigma_m_s": VEL_SIGMA_M_S,
            "noise": asdict(base),
        },
        "tracks": track_results,
    }
    for track_name, track in tracks.items():
        per_case: dict[str, dict[str, float | None]] = {}
        for case_name, model, noise in cases:
            per_case[case_name] = evaluate(track, noise, model, args.runs, args.seed)
            _log.info("%-28s %-34s %s", track_name, case_name, per_case[case_name])
        track_results[track_name] = per_case
    write_figures(args.json, results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
