"""``--json FILE`` kept up to date while the campaign flies: the missions that ended so far, written at most every
``--checkpoint-s`` (atomically, as the last write is), so that a campaign killed outright (SIGKILL, a machine that
stops) loses at most that much of its flight; ``--resume`` flies on from the file. The file says what it holds as a
stopped campaign's does: fewer missions than ``episodes_requested`` is a campaign not yet whole, which pooling refuses
and ``--resume`` completes. Only a regular file (or one not there yet) is written so: a named pipe or a character
device (``--json /dev/stdout``) gets the campaign's one record at its end."""

from __future__ import annotations

import logging
import time
from pathlib import Path

from mavlink_bridge.fly.config import FlyConfig
from mavlink_bridge.fly.mission_row import MissionRow
from mavlink_bridge.fly.scoring import campaign_results
from tssac_core.common.cli import bad_input_line, write_json

_log = logging.getLogger(__name__)


def _regular_target(path: Path) -> bool:
    return not path.exists() or path.is_file()


class Checkpoint:
    """Called with the rows flown so far after every mission that ends (:func:`mavlink_bridge.fly.cli.fly_campaign`);
    writes the file when ``cfg.checkpoint_s`` has passed since the last write (a write is the whole file). A write
    that fails is said once and the campaign flies on: its last write, at the end, says it again and decides the exit
    code."""

    def __init__(self, cfg: FlyConfig, key: str, started_s: float) -> None:
        self.path = cfg.json_path if cfg.json_path is not None and _regular_target(cfg.json_path) else None
        self.cfg, self.key, self.started_s, self.every_s = cfg, key, started_s, cfg.checkpoint_s
        self.last_s = started_s
        self.failed = False

    def __call__(self, rows: list[MissionRow]) -> None:
        now = time.monotonic()
        if self.path is None or self.failed or now - self.last_s < self.every_s:
            return
        self.last_s = now
        results = campaign_results(list(rows), self.cfg, False, None, now - self.started_s, self.key)
        try:
            write_json(self.path, results.to_json())
        except OSError as exc:
            self.failed = True
            line = bad_input_line(exc)
            _log.warning("could not write the campaign so far (%s); it is written again at its end", line)
