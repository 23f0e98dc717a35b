"""The companion's decision time: one actor call on one observation, the ONNX actor against the numpy actor.

Both actors of one role (``models/tssac/<role>.npz`` and its ``export --format onnx``) are called in one run, in turns
(numpy then ONNX on even calls, ONNX then numpy on odd ones, each on the same observation), so that whatever else the
machine does falls on both alike. Each call is timed alone (``time.perf_counter_ns``); the figures are the median and
the 99th percentile over the calls, and their ratio ONNX / numpy (target: within 2x). A batch of observations (the
batched evaluation's call) is timed too, for reference.

    python benchmarks/bench_onnx.py [--role strike] [--calls 20000] [--json FILE]

The JSON goes where ``--json`` says, by default under the system's temporary directory (never into the checkout).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.output import add_json_option, write_figures  # noqa: E402
from tssac_core.common.cli import command_description  # noqa: E402
from tssac_core.deploy.export import export_onnx  # noqa: E402
from tssac_core.deploy.numpy_actor import NumpyPolicy  # noqa: E402
from tssac_core.deploy.onnx_actor import OnnxPolicy  # noqa: E402
from tssac_core.sim.observation import observation_bounds  # noqa: E402
from tssac_core.sim.scenario import Role  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
TARGET_RATIO = 2.0
"""The target: the ONNX actor's median decision time within this factor of the numpy actor's."""

Actor = Callable[[np.ndarray], np.ndarray]


@dataclasses.dataclass(frozen=True)
class CallTimes:
    """One actor's call times in microseconds."""

    median_us: float
    p99_us: float
    mean_us: float
    min_us: float

    @staticmethod
    def of(ns: np.ndarray) -> CallTimes:
        us = ns / 1e3
        return CallTimes(
            median_us=float(np.median(us)),
            p99_us=float(np.percentile(us, 99)),
            mean_us=float(np.mean(us)),
            min_us=float(np.min(us)),
        )


@dataclasses.dataclass(frozen=True)
class Result:
    """What the benchmark measured, as its JSON says it."""

    role: str
    calls: int
    numpy: CallTimes
    onnx: CallTimes
    ratio_median: float
    ratio_p99: float
    target_ratio: float
    met: bool
    batch: int
    batch_numpy_us: float
    batch_onnx_us: float
    max_abs_action_difference: float
    versions: dict[str, str]
    threads_started_by_onnxruntime: int | None
    """Threads the process gained while the ONNX session was made (None where /proc is not): 0, as it runs on the
    caller's thread."""
    cpus: int
    load_average_1min: float


def interleaved(actors: Sequence[Actor], obs: np.ndarray, warmup: int) -> list[np.ndarray]:
    """Each actor's call time (ns) on each observation of ``obs`` (n, d), calling them in turns: the order flips every
    call (so neither always runs second, in the caches the other left)."""
    for o in obs[:warmup]:
        for actor in actors:
            actor(o)
    times = np.zeros((len(actors), len(obs)), dtype=np.int64)
    order = list(range(len(actors)))
    for i, o in enumerate(obs):
        for k in order if i % 2 == 0 else order[::-1]:
            t0 = time.perf_counter_ns()
            actors[k](o)
            times[k, i] = time.perf_counter_ns() - t0
    return list(times)


def batch_time_us(actor: Actor, obs: np.ndarray, repeats: int = 20) -> float:
    """The median time of one call on the whole batch ``obs`` (n, d), microseconds."""
    actor(obs)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        actor(obs)
        times.append(time.perf_counter_ns() - t0)
    return float(np.median(times)) / 1e3


def thread_count() -> int | None:
    """This process's threads now (Linux), else None."""
    tasks = Path("/proc/self/task")
    return len(list(tasks.iterdir())) if tasks.is_dir() else None


def measure(models: Path, onnx_dir: Path, role: Role, calls: int, batch: int, seed: int) -> Result:
    numpy_actor = NumpyPolicy.load(models / f"{role.value}.npz", role)
    import onnxruntime  # noqa: F401  (before the count: what importing it starts is not the session's)

    before = thread_count()
    onnx_actor = OnnxPolicy.load(onnx_dir / f"{role.value}.onnx", role)
    after = thread_count()
    low, high = observation_bounds(numpy_actor.observation_mode)
    obs = np.random.default_rng(seed).uniform(low, high, (calls, low.size)).astype(np.float32)
    numpy_ns, onnx_ns = interleaved([numpy_actor, onnx_actor], obs, warmup=min(1000, calls))
    t_numpy, t_onnx = CallTimes.of(numpy_ns), CallTimes.of(onnx_ns)

    return Result(
        role=role.value,
        calls=calls,
        numpy=t_numpy,
        onnx=t_onnx,
        ratio_median=t_onnx.median_us / t_numpy.median_us,
        ratio_p99=t_onnx.p99_us / t_numpy.p99_us,
        target_ratio=TARGET_RATIO,
        met=t_onnx.median_us <= TARGET_RATIO * t_numpy.median_us,
        batch=batch,
        batch_numpy_us=batch_time_us(numpy_actor, obs[:batch]),
        batch_onnx_us=batch_time_us(onnx_actor, obs[:batch]),
        max_abs_action_difference=float(np.abs(onnx_actor(obs) - numpy_actor(obs)).max()),
        versions={"onnxruntime": onnxruntime.__version__, "numpy": np.__version__, "python": platform.python_version()},
        threads_started_by_onnxruntime=None if before is None or after is None else after - before,
        cpus=os.cpu_count() or 0,
        load_average_1min=os.getloadavg()[0],
    )


def report(r: Result) -> str:
    rows = [
        f"decision time of the {r.role} actor, one observation, {r.calls} calls each, in turns "
        f"(load average {r.load_average_1min:.1f} on {r.cpus} CPUs):",
        f"  numpy  median {r.numpy.median_us:7.1f} us  p99 {r.numpy.p99_us:8.1f} us  (mean {r.numpy.mean_us:.1f})",
        f"  onnx   median {r.onnx.median_us:7.1f} us  p99 {r.onnx.p99_us:8.1f} us  (mean {r.onnx.mean_us:.1f}, "
        f"onnxruntime {r.versions['onnxruntime']}, threads it started: {r.threads_started_by_onnxruntime})",
        f"  onnx / numpy: median {r.ratio_median:.2f}x, p99 {r.ratio_p99:.2f}x "
        f"(target: median within {r.target_ratio:g}x: {'met' if r.met else 'NOT met'})",
        f"  a batch of {r.batch}: numpy {r.batch_numpy_us:.0f} us, onnx {r.batch_onnx_us:.0f} us; largest action "
        f"difference {r.max_abs_action_difference:.1e}",
    ]
    return "\n".join(rows)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    p.add_argument("--models", type=Path, default=REPO / "models" / "tssac", help="the numpy actors (default shipped)")
    p.add_argument("--role", choices=[r.value for r in Role], default=Role.STRIKE.value, help="default strike")
    p.add_argument("--calls", type=int, default=20_000, help="timed calls per actor (default 20000)")
    p.add_argument("--batch", type=int, default=1000, help="observations in the batch call (default 1000)")
    p.add_argument("--seed", type=int, default=0, help="the observations' seed (default 0)")
    add_json_option(p, "onnx")
    args = p.parse_args(argv)
    if args.calls < 100 or args.batch < 1:
        p.error("--calls must be >= 100 and --batch >= 1")
    with tempfile.TemporaryDirectory(prefix="bench-onnx-") as tmp:
        export_onnx(args.models, Path(tmp))
        result = measure(args.models, Path(tmp), Role(args.role), args.calls, min(args.batch, args.calls), args.seed)
    print(report(result))
    write_figures(args.json, dataclasses.asdict(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
