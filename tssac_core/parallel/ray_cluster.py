"""Where Ray work runs: a Ray started inside the command (the default), or an existing cluster (``--address``).

:func:`ray_session` is the one place that calls ``ray.init``. Without an address it starts a local Ray
in the command's own process tree, with the machine's CPUs (or ``cpus``), a small object store (the
tasks exchange run directories' names and mission results, not data sets) and no dashboard, and shuts
it down on the way out: nothing to install or start by hand. With an address (``HOST:PORT`` of a head
node started with ``ray start --head``, or ``auto``) it joins that cluster and leaves it running; the
workers then import this checkout (``PYTHONPATH`` is passed to them), so every node must see it at the
same path (docs/ray.md). If Ray is already initialised in this process (a test's module fixture, a
notebook), that Ray is used and left as it is.

``ray.init`` replaces the process's SIGTERM handler with Ray's own (``sys.exit``, which none of the commands'
interrupt paths catches: ``fly --workers`` died without its JSON and left Ray's node agent orphaned). The session
puts the command's handler back; a command without one gets SIGTERM as KeyboardInterrupt (Ctrl-C) for the length of
the session, so that Ray is shut down on the way out rather than left behind by an instant death.

Ray is imported here and in the modules that submit tasks only when they are used: the serial paths
never pay its import.
"""

from __future__ import annotations

import logging
import os
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import Any

from tssac_core.common.cli import UsageError

PROJECT_ROOT = Path(__file__).resolve().parents[2]
"""The checkout whose tssac_core, sim_vehicles and mavlink_bridge the workers import."""
OBJECT_STORE_BYTES = 128 * 2**20
"""The local Ray's shared-memory object store: mission results and small arguments only."""
RAY_ENVIRONMENT = {
    "RAY_USAGE_STATS_ENABLED": "0",  # no usage reports sent from the user's machine
    # A local Ray's workers run at the command's own priority, as the local executor's jobs do (Ray's default
    # lowers them by 15: a training job on a busy machine would wait behind everything else)
    "RAY_worker_niceness": "0",
    "RAY_ACCEL_ENV_VAR_OVERRIDE_ON_ZERO": "0",  # CPU-only tasks: no accelerator variables touched, no warning about it
    # Lines Ray's log monitor forwards from its own processes (raylet, gcs_server) to the command's stderr, dropped:
    # without its [default] extra Ray has no metrics agent and each process says so once; and each one announces the
    # log level below ("Set ray log level from environment variable"), at any time after ``ray.init`` returns
    "RAY_DEDUP_LOGS_SKIP_REGEX": "metrics exporter agent|Set ray log level",
    # ... and so does the command's own process, from Ray's C++ core (no Python logger, no dedup: "Failed to establish
    # connection to the metrics exporter agent", some 30 s after the start): Ray's C++ logs on the console only for a
    # fatal error. The logs in Ray's session directory stay as they are. RAY_enable_metrics_collection=0 does not stop
    # the core from waiting for the agent (ray 2.52).
    "RAY_BACKEND_LOG_LEVEL": "fatal",
}
"""Set (unless the user set them) before Ray is imported."""


@dataclass(frozen=True)
class RayTarget:
    """Which Ray to use."""

    address: str | None = None
    """An existing cluster (``HOST:PORT`` or ``auto``); None: start a local Ray inside the command."""
    cpus: int | None = None
    """CPUs of the local Ray (default: the machine's); ignored with an address (the cluster has its own)."""


RAY_MISSING = "Ray is not installed: pip install -e '.[ray]' (in '.[dev]' too)"
"""The one line for a command that needs Ray (``--workers N``, ``--executor ray``, ``--address``) without it."""


def import_ray() -> Any:
    """``ray``, imported with :data:`RAY_ENVIRONMENT` set; UsageError (:data:`RAY_MISSING`) without Ray."""
    for key, value in RAY_ENVIRONMENT.items():
        os.environ.setdefault(key, value)
    try:
        import ray
    except ImportError:
        raise UsageError(RAY_MISSING) from None
    return ray


@contextmanager
def _quiet_backend_start() -> Iterator[None]:
    """The process's stderr to /dev/null for the block when Ray's C++ logs are ours (:data:`RAY_ENVIRONMENT`): setting
    that log level prints a line of its own from ``ray.init`` ("Set ray log level from environment variable"). A failing
    ``ray.init`` still raises: its one line is the command's."""
    if os.environ.get("RAY_BACKEND_LOG_LEVEL") != RAY_ENVIRONMENT["RAY_BACKEND_LOG_LEVEL"]:
        yield
        return
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        sys.stderr.flush()
        os.dup2(saved, 2)
        os.close(saved)


def worker_pythonpath() -> str:
    """``PYTHONPATH`` for workers: this checkout first, then what the driver has."""
    return os.pathsep.join(p for p in (str(PROJECT_ROOT), os.environ.get("PYTHONPATH", "")) if p)


@contextmanager
def ray_session(target: RayTarget) -> Iterator[Any]:
    """Ray initialised as ``target`` says for the length of the block (module docstring); yields ``ray``.

    An unreachable address is a UsageError (one line), not a traceback."""
    ray = import_ray()
    if ray.is_initialized():
        yield ray
        return
    main_thread = threading.current_thread() is threading.main_thread()
    sigterm = signal.getsignal(signal.SIGTERM) if main_thread else None
    try:
        with _quiet_backend_start():
            _init(ray, target)
    except (ConnectionError, ValueError, RuntimeError) as exc:
        what = f"reach the Ray cluster at {target.address}" if target.address is not None else "start a local Ray"
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if sigterm is not None:
            signal.signal(signal.SIGTERM, sigterm)
        raise UsageError(f"cannot {what}: {first}") from None
    if sigterm is not None:  # the command's handler, not Ray's sys.exit (module docstring)
        signal.signal(signal.SIGTERM, _interrupt if sigterm is signal.SIG_DFL else sigterm)
    try:
        yield ray
    finally:
        ray.shutdown()
        if sigterm is not None:
            signal.signal(signal.SIGTERM, sigterm)


def _init(ray: Any, target: RayTarget) -> None:
    """``ray.init`` as ``target`` says."""
    if target.address is not None:
        # Workers on other nodes do not inherit the driver's environment: point them at this checkout.
        ray.init(
            address=target.address,
            runtime_env={"env_vars": {"PYTHONPATH": worker_pythonpath()}},
            logging_level=logging.WARNING,
        )
    else:
        # A local Ray's workers are the driver's children: they inherit its environment and directory.
        ray.init(
            num_cpus=target.cpus or os.cpu_count() or 1,
            object_store_memory=OBJECT_STORE_BYTES,
            include_dashboard=False,
            logging_level=logging.WARNING,
        )


def _interrupt(signum: int, _frame: FrameType | None) -> None:
    """SIGTERM as Ctrl-C, for a command with no SIGTERM handler of its own."""
    raise KeyboardInterrupt(f"signal {signum}")


def cluster_cpus(ray: Any) -> int:
    """The CPUs of the Ray this process is connected to (at least 1)."""
    return max(1, int(ray.cluster_resources().get("CPU", 1)))
