"""A training run as a job: what it trains (a row of the tables, its configuration) and where it writes. The grid's
runs, the transfer experiment's and ``train --seeds`` are all jobs, run by the executors
(tssac_core.train.jobs.executors) and judged from their run directories alone (tssac_core.train.jobs.runner)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from tssac_core.train.config import TrainConfig


@dataclass(frozen=True)
class AlgoEntry:
    """One row of the tables: a name and the training configuration of its runs (every seed's but for the seed)."""

    name: str
    """Label in tables and figures, and the prefix of its run directories (default: the algorithm)."""
    config: TrainConfig
    """The row's runs' configuration (its seed: the preset's, replaced by each job's)."""

    @property
    def algo(self) -> str:
        return self.config.algo

    @property
    def penalty(self) -> float:
        """sac_penalty only: reward r + penalty * c."""
        return self.config.penalty


@dataclass(frozen=True)
class Job:
    """One training run of the grid: a whole team, or one role of the transfer experiment."""

    entry: AlgoEntry
    config: TrainConfig
    """What the run trains (its config.json: `tssac_core.train.config.config_record`); the seed is the job's."""
    out: Path
    role: str | None = None
    """The transfer experiment's role (the run trains that role only); None: the whole curriculum."""
    tensorboard: Path | None = None
    """Where the run also writes TensorBoard events (``train --seeds --tensorboard``); None: nowhere."""

    @property
    def seed(self) -> int:
        return self.config.seed

    @property
    def name(self) -> str:
        return (
            f"{self.entry.name}-seed{self.seed}"
            if self.role is None
            else f"transfer-{self.role}-{self.entry.name}-seed{self.seed}"
        )

    @property
    def roles(self) -> tuple[str, ...]:
        """The roles this run trains (and whose checkpoints mark it finished)."""
        return self.config.roles if self.role is None else (self.role,)
