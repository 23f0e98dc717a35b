"""``fly --workers N``: the SITL missions as Ray tasks, N at once, each on its own ports.

Mission ``i`` is one task: the worker flies it with its own world (``--base-port 0``: the OS gives each
world its own ports, so missions side by side never meet) and three companions exactly as the serial run
does, from the same layout and seed (``mission_layout(scenario, seed, i)``, seed ``S + i``), and returns the
same row. The world and companions stay alive in the worker for its next mission of the same run (reset
between missions, as in the serial run). A worker that dies takes its processes with it (they die with their
parent) and Ray flies the mission again. The rows are merged in index order into the serial run's JSON. A
signing key that fly made (a scenario with signing and no ``--signing-key``) travels with the task;
``--models``, ``--logs``, ``--tlog`` and ``--plot`` are paths the worker opens, so on a cluster they must be on a
filesystem every node sees (docs/ray.md).
"""

from __future__ import annotations

import dataclasses
import tempfile
from collections.abc import Callable
from pathlib import Path

from mavlink_bridge.fly.config import FlyConfig
from mavlink_bridge.fly.mission_row import MissionRow
from mavlink_bridge.fly.mission_runner import MissionRunner
from mavlink_bridge.processes.children import ChildProcesses
from tssac_core.parallel.ray_cluster import RayTarget
from tssac_core.parallel.ray_map import map_on_ray


@dataclasses.dataclass(frozen=True)
class MissionTask:
    """What a worker needs to fly one mission."""

    cfg: FlyConfig
    index: int
    signing_key: bytes | None
    """The key fly made for this invocation (None: none, or the user's ``--signing-key`` file)."""


@dataclasses.dataclass
class _WorkerRun:
    """What a Ray worker keeps between its tasks of one fly run: its crew of processes (``cfg.persistent``)."""

    task: MissionTask
    children: ChildProcesses
    runner: MissionRunner
    tmp: tempfile.TemporaryDirectory[str]

    def close(self) -> None:
        try:
            self.runner.close()
        finally:
            self.children.stop_all()
            self.tmp.cleanup()


class _MissionTasks:
    """The run's tasks, each made when it is submitted: their memory does not grow with ``--episodes``."""

    def __init__(self, cfg: FlyConfig, signing_key: bytes | None) -> None:
        self.cfg = cfg
        self.signing_key = signing_key
        self.indices = cfg.indices()

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, position: int) -> MissionTask:
        return MissionTask(self.cfg, self.indices[position], self.signing_key)


_kept: _WorkerRun | None = None
"""This worker process's run (one at a time: a task of another fly run replaces it)."""


def _worker_run(task: MissionTask) -> _WorkerRun:
    global _kept
    same = _kept is not None and dataclasses.replace(_kept.task, index=0) == dataclasses.replace(task, index=0)
    if _kept is not None and not same:
        _kept.close()
        _kept = None
    if _kept is None:
        tmp = tempfile.TemporaryDirectory(prefix="tssac-fly-")
        cfg = task.cfg
        if task.signing_key is not None:
            key = Path(tmp.name) / "signing.key"
            key.write_bytes(task.signing_key)
            key.chmod(0o600)
            cfg = dataclasses.replace(cfg, signing_key_path=key)
        children = ChildProcesses()
        _kept = _WorkerRun(task, children, MissionRunner(cfg, children, cfg.logs_dir or Path(tmp.name)), tmp)
    return _kept


def fly_mission(task: MissionTask) -> MissionRow:
    """The Ray task: one mission, flown by the worker's crew of processes (kept for its next mission of the same
    run when ``cfg.persistent``), or by processes of its own, stopped whatever happens (a cancel arrives as
    KeyboardInterrupt)."""
    global _kept
    run = _worker_run(task)
    try:
        row = run.runner.fly(task.index)
    except BaseException:
        run.close()
        _kept = None
        raise
    if not task.cfg.persistent:
        run.close()
        _kept = None
    return row


def fly_on_workers(
    cfg: FlyConfig, workers: int, target: RayTarget, made_key: Path | None, on_row: Callable[[MissionRow], None]
) -> None:
    """Fly the missions of ``cfg.indices()``, ``workers`` at once; ``on_row`` gets each row as its mission ends (so an
    interruption keeps the finished ones). Raises TaskFailed for a mission whose processes failed."""
    key = made_key.read_bytes() if made_key is not None else None
    map_on_ray(
        fly_mission, _MissionTasks(cfg, key), workers, target, on_result=lambda i, row: on_row(row), collect=False
    )
