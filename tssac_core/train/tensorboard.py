"""``train --tensorboard DIR``: every epoch's metrics row as TensorBoard scalars, while training runs.

The rows are those of ``metrics.csv`` (:data:`tssac_core.train.rundir.METRIC_FIELDS`); each role gets its own
section, the epoch is the step (figures 7 and 8 are per epoch):

    <role>/return, <role>/cost, <role>/hazard_cost, <role>/task_success, <role>/mission_success   training episodes
    <role>/multiplier/beta, .../xi, .../beta_minus_xi, <role>/alpha                                eq. 15-17, eq. 14
    <role>/loss/q_r, .../q_c, .../actor, .../alpha, .../beta                                       eq. 12-15
    <role>/validation/mission_success, .../task_success, .../cost, .../cost_high, .../within_limit,
        .../cvar95_cost, .../max_cost                                                              held-out missions
    <role>/speed/env_steps_per_s, .../updates_per_s

A figure an epoch does not have (no episode ended, an on-policy learner's missing SAC terms, no validation)
is left out rather than written as NaN. The writer is torch's ``SummaryWriter``, which needs the
``tensorboard`` package (the ``tensorboard`` extra); the CLI checks for it before training starts.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:  # the loop's module imports torch; this one must not
    from tssac_core.train.rundir import MetricsRow

TAGS: dict[str, str] = {
    "return": "return",
    "cost": "cost",
    "hazard_cost": "hazard_cost",
    "task_success": "task_success",
    "mission_success": "mission_success",
    "beta": "multiplier/beta",
    "xi": "multiplier/xi",
    "beta_minus_xi": "multiplier/beta_minus_xi",
    "alpha": "alpha",
    "entropy": "entropy",
    "q_r_loss": "loss/q_r",
    "q_c_loss": "loss/q_c",
    "actor_loss": "loss/actor",
    "alpha_loss": "loss/alpha",
    "beta_loss": "loss/beta",
    "qc_mean": "q_c_mean",
    "cost_signal": "multiplier/cost_signal",
    "val_mission_success": "validation/mission_success",
    "val_task_success": "validation/task_success",
    "val_cost": "validation/cost",
    "val_cost_high": "validation/cost_high",
    "val_within_limit": "validation/within_limit",
    "val_cvar95_cost": "validation/cvar95_cost",
    "val_max_cost": "validation/max_cost",
    "env_steps_per_s": "speed/env_steps_per_s",
    "updates_per_s": "speed/updates_per_s",
}
"""metrics.csv column -> its tag under the role's section."""


class EpochSink(Protocol):
    """Where the training loop hands each epoch's metrics row."""

    def write(self, row: MetricsRow) -> None: ...

    def close(self) -> None: ...


def scalars(row: MetricsRow) -> dict[str, float]:
    """The TensorBoard scalars of one metrics row: ``{"<role>/<tag>": value}``, finite numbers only."""
    role = row.role.value
    out: dict[str, float] = {}
    for column, tag in TAGS.items():
        value = row.figures.get(column)
        if isinstance(value, bool) or not isinstance(value, int | float):
            continue
        if math.isfinite(value):
            out[f"{role}/{tag}"] = float(value)
    return out


class TensorBoardSink:
    """Writes each row's :func:`scalars` at step = the row's epoch, and flushes, so that TensorBoard shows the
    epoch as soon as it ends."""

    def __init__(self, log_dir: Path) -> None:
        from torch.utils.tensorboard import SummaryWriter

        self.writer = SummaryWriter(log_dir=str(log_dir))

    def write(self, row: MetricsRow) -> None:
        step = int(row.figures["epoch"])
        for tag, value in scalars(row).items():
            self.writer.add_scalar(tag, value, step)
        self.writer.flush()

    def close(self) -> None:
        self.writer.close()


def open_sink(log_dir: Path) -> EpochSink:
    """A :class:`TensorBoardSink` writing into ``log_dir`` (created if missing)."""
    log_dir.mkdir(parents=True, exist_ok=True)
    return TensorBoardSink(log_dir)
