"""``python -m mavlink_bridge.fly``: fly whole missions (see :mod:`mavlink_bridge.fly`)."""

from __future__ import annotations

import dataclasses
import logging
import signal
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import FrameType

import numpy as np

from mavlink_bridge.fly.checkpoint import Checkpoint
from mavlink_bridge.fly.config import PROG, FlyConfig, config_from_args, make_signing_key
from mavlink_bridge.fly.mission_row import MissionRow
from mavlink_bridge.fly.mission_runner import ChildFailed, MissionRunner, WorldRefused
from mavlink_bridge.fly.report import print_report
from mavlink_bridge.fly.resume import campaign_key, resumed_rows
from mavlink_bridge.fly.scoring import CampaignResults, campaign_results
from mavlink_bridge.fly.side_by_side import fly_side_by_side
from mavlink_bridge.fly.workers import fly_on_workers
from mavlink_bridge.processes.children import ChildProcesses
from tssac_core.common.cli import BAD_INPUT, EXIT_BAD_INPUT, EXIT_INTERRUPTED, bad_input_line, write_json
from tssac_core.common.files import private_directory
from tssac_core.parallel.ray_cluster import RayTarget
from tssac_core.parallel.ray_map import TaskFailed
from tssac_core.reporting.progress import progress_bar

EXIT_FAILED = 1


class MissionTimedOut(Exception):
    """A mission did not end in --mission-timeout-s: no further mission is flown; ``str()`` is one line."""


class WriteFailed(Exception):
    """A mission's record was not all written (a tlog cut by a full disk): no further mission is flown, whose records
    would be lost too; ``str()`` is one line."""


class _Terminated(KeyboardInterrupt):
    """SIGTERM, handled like Ctrl-C."""


def _on_sigterm(signum: int, _frame: FrameType | None) -> None:
    raise _Terminated()


def fly_campaign(
    cfg: FlyConfig,
    children: ChildProcesses,
    work: Path,
    made_key: Path | None,
    rows: list[MissionRow],
    checkpoint: Callable[[list[MissionRow]], None] = lambda rows: None,
) -> None:
    """Fly the campaign's missions (one crew here, crews side by side, or Ray tasks), each mission's row appended to
    ``rows`` as it ends; the first mission that did not end in time, or whose companion lost a write, ends the
    campaign (MissionTimedOut, WriteFailed). ``made_key``: the signing key fly made for this run, if it made one;
    ``checkpoint`` is called with the rows after each (:class:`~mavlink_bridge.fly.checkpoint.Checkpoint`)."""
    with progress_bar(total=len(cfg.indices()), desc="missions", unit="mission", disable=not cfg.progress) as bar:

        def record(row: MissionRow) -> None:
            rows.append(row)
            checkpoint(rows)
            bar.update(1)
            bar.set_postfix(success=f"{np.mean([bool(r.get('success')) for r in rows]):.0%}")
            if row.get("end") == "timeout":
                raise MissionTimedOut(f"mission {row['index']} did not end within {cfg.mission_timeout_s:g} s")
            lost = [f"{name}: {s['write_error']}" for name, s in row["companions"].items() if s.get("write_error")]
            if lost:
                raise WriteFailed(f"mission {row['index']}: {'; '.join(lost)}")

        if cfg.on_ray:
            fly_on_workers(cfg, cfg.workers, RayTarget(cfg.ray_address), made_key, record)
        elif cfg.workers > 1:
            fly_side_by_side(cfg, cfg.workers, work, record)
        else:
            runner = MissionRunner(cfg, children, work)
            try:
                for i in cfg.indices():
                    row = runner.fly(i)
                    children.forget_finished()
                    record(row)
            finally:
                runner.close()


def campaign_error(exc: Exception) -> tuple[str, int] | None:
    """How a campaign that raised ``exc`` ended: its error line and exit code (None: a defect, to be re-raised)."""
    if isinstance(exc, (MissionTimedOut, WriteFailed, TaskFailed)):
        return str(exc), EXIT_FAILED
    if isinstance(exc, WorldRefused):  # before any mission flew: bad input, and no JSON of a campaign that never began
        return str(exc), EXIT_BAD_INPUT
    if isinstance(exc, ChildFailed):
        return str(exc), EXIT_FAILED
    if isinstance(exc, BAD_INPUT):
        return bad_input_line(exc), EXIT_BAD_INPUT
    if isinstance(exc, MemoryError):
        return "out of memory", EXIT_FAILED
    return None


def prepare(cfg: FlyConfig, tmp: Path) -> tuple[FlyConfig, Path, Path | None]:
    """The campaign's private directories (``--tlog``; ``--logs``, else ``tmp``) and its signing key, made there when
    it asks for one: the config that flies (with the key), the working directory, and the key made."""
    if cfg.tlog_dir is not None:
        private_directory(cfg.tlog_dir, "--tlog")
    work = private_directory(cfg.logs_dir, "--logs") if cfg.logs_dir is not None else tmp
    if not cfg.makes_key:
        return cfg, work, None
    made_key = make_signing_key(work)
    return dataclasses.replace(cfg, signing_key_path=made_key), work, made_key


def write_results(cfg: FlyConfig, results: CampaignResults, code: int) -> tuple[FlyConfig, int]:
    """``--json``, unless the campaign never began (bad input before any mission); a write that fails is said here and
    is no exit 0 (the config comes back without the file it did not write)."""
    if cfg.json_path is None or (code == EXIT_BAD_INPUT and not results.missions):
        return cfg, code
    try:
        write_json(cfg.json_path, results.to_json())
    except OSError as exc:  # the campaign's record is lost: said here, and not an exit 0
        print(f"{PROG}: error: {bad_input_line(exc)}", file=sys.stderr)
        return dataclasses.replace(cfg, json_path=None), code or EXIT_FAILED
    return cfg, code


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(levelname)s %(name)s: %(message)s")
    try:
        cfg = config_from_args(argv)
        key = campaign_key(cfg)
        rows: list[MissionRow] = resumed_rows(cfg, key) if cfg.resume else []
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BAD_INPUT as exc:
        print(f"{PROG}: error: {bad_input_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if rows:
        cfg = dataclasses.replace(cfg, done=frozenset(row["index"] for row in rows))
        print(f"resuming: {len(rows)} missions flown, {len(cfg.indices())} to fly", file=sys.stderr)
    previous = signal.signal(signal.SIGTERM, _on_sigterm)
    children = ChildProcesses()
    error: str | None = None
    interrupted = False
    code = 0
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="tssac-fly-") as tmp:
        try:
            cfg, work, made_key = prepare(cfg, Path(tmp))
            fly_campaign(cfg, children, work, made_key, rows, Checkpoint(cfg, key, started))
        except KeyboardInterrupt:
            interrupted, code = True, EXIT_INTERRUPTED
        except Exception as exc:
            ended = campaign_error(exc)
            # a defect: the JSON must not say that nothing went wrong, and the traceback follows
            error, code = ended or (f"internal error: {type(exc).__name__}: {exc}", EXIT_FAILED)
            if ended is None:
                raise
        finally:
            # No second signal may cut the clean-up short: the children are in their own sessions.
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
            previous_int = signal.signal(signal.SIGINT, signal.SIG_IGN)
            children.stop_all()
            signal.signal(signal.SIGTERM, previous)
            signal.signal(signal.SIGINT, previous_int)
            results = campaign_results(rows, cfg, interrupted, error, time.monotonic() - started, key)
            cfg, code = write_results(cfg, results, code)
    print_report(results, cfg)
    if interrupted:
        print(
            f"interrupted after {len(rows)} of {cfg.episodes} missions"
            + (f"; wrote {cfg.json_path}" if cfg.json_path else ""),
            file=sys.stderr,
        )
    if error is not None:
        print(f"{PROG}: error: {error}", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
