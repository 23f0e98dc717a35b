"""``train --seeds``: one job per seed, each the single run of that seed, resumable as a whole."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from tiny_training import tiny_args

from tssac_core.train.cli import main

TINY = tiny_args()
TIMING = {"env_steps_per_s", "updates_per_s"}


def metrics(run: Path) -> list[dict[str, str]]:
    with (run / "metrics.csv").open() as fh:
        return [{k: v for k, v in row.items() if k not in TIMING} for row in csv.DictReader(fh)]


@pytest.mark.slow
def test_each_seed_is_its_single_run_and_the_whole_resumes(tmp_path: Path, capsys):
    out = tmp_path / "seeds"
    assert main([*TINY, "--seeds", "0,1", "--out", str(out)]) == 0
    assert json.loads((out / "seeds.json").read_text()) == {"seeds": [0, 1]}
    for seed in (0, 1):
        assert (out / f"seed{seed}" / "decoy.pt").is_file()
        assert json.loads((out / f"seed{seed}" / "config.json").read_text())["seed"] == seed
    single = tmp_path / "single1"
    assert main([*TINY, "--seed", "1", "--out", str(single)]) == 0
    assert metrics(out / "seed1") == metrics(single)  # the same numbers as the single run of seed 1
    assert metrics(out / "seed0") != metrics(out / "seed1")
    # Everything is finished: --resume runs nothing and succeeds; a second start refuses (one line, exit 2).
    assert main(["--out", str(out), "--resume", "--no-progress"]) == 0
    from tssac_core.common.cli import run

    assert run(main, [*TINY, "--seeds", "0,1", "--out", str(out)]) == 2
    assert "already holds a run" in capsys.readouterr().err
