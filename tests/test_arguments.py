"""Arguments at their edges: every command refuses a value it cannot fly with one line and exit 2 (argparse's), before
any process starts, and a campaign of any size starts in bounded memory (issue 61, item 6)."""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from mavlink_bridge.companion.config import CompanionConfig
from mavlink_bridge.fly import cli as fly
from tssac_core.common.cli import UsageError
from tssac_core.sim.scenario import Role, load

REPO = Path(__file__).resolve().parents[1]
STRIKE = REPO / "scenarios" / "strike.yaml"


def _one_line_exit_2(code: int | str | None, err: str, needle: str) -> None:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, (code, err)
    assert lines and needle in lines[-1] and "Traceback" not in err, err


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--seed", "-1"], "invalid seed -1"),
        (["--seed", "x"], "invalid seed 'x'"),
        (["--seed", str(2**63)], "invalid seed"),
        (["--seed", str(2**63 - 1), "--episodes", "2"], "--seed plus the last mission's index"),
        (["--lockstep-grant-s", "1e308"], "--lockstep-grant-s must be 0 to 60"),
        (["--lockstep-grant-s", "61"], "--lockstep-grant-s must be 0 to 60"),
        (["--lockstep-grant-s", "nan"], "--lockstep-grant-s"),
    ],
)
def test_fly_refuses_a_seed_or_grant_it_cannot_fly_in_one_line(
    argv: list[str], needle: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out.json"
    code = fly.main(["--scenario", str(STRIKE), "--pilot", "guidance", "--json", str(out), *argv])
    err = capsys.readouterr().err
    _one_line_exit_2(code, err, needle)
    assert not out.exists()  # nothing flew: no campaign JSON


def test_the_companion_refuses_a_grant_its_clock_cannot_count() -> None:
    scenario = load(STRIKE)
    CompanionConfig("udpout:127.0.0.1:1", Role.DECOY, scenario, lockstep_grant_s=60.0)
    with pytest.raises(UsageError, match="--lockstep-grant-s must be 0 to 60"):
        CompanionConfig("udpout:127.0.0.1:1", Role.DECOY, scenario, lockstep_grant_s=1e308)


@pytest.mark.parametrize(
    "module, argv",
    [
        ("tssac_core.evaluate", ["--controller", "guidance", "--episodes", "1", "--seed", "-1"]),
        ("tssac_core.train", ["--seed", "-1", "--out", "OUT"]),
        ("tssac_core.train", ["--seeds", "0,-1", "--out", "OUT"]),
        ("sim_vehicles", ["--scenario", str(STRIKE), "--seed", "-1"]),
        ("tssac_core.experiments.targets", ["TEAM", "--seed", "-1"]),
    ],
)
def test_every_command_refuses_a_negative_seed_in_one_line(module: str, argv: list[str], tmp_path: Path) -> None:
    argv = [a.replace("OUT", str(tmp_path / "run")).replace("TEAM", str(tmp_path)) for a in argv]
    proc = subprocess.run(
        [sys.executable, "-m", module, *argv],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        timeout=120,
    )
    _one_line_exit_2(proc.returncode, proc.stderr, "seed")
    assert not (tmp_path / "run").exists()


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))


FLY_MANY = textwrap.dedent(
    """
    import json, sys
    from pathlib import Path
    from mavlink_bridge.fly import side_by_side
    from mavlink_bridge.fly.config import config_from_args

    class Runner:  # a crew that flies a mission in no time
        def __init__(self, cfg, children, work_dir, children_cpu=True):
            pass
        def fly(self, index):
            return {"index": index}
        def close(self):
            pass

    class Enough(Exception):
        pass

    side_by_side.MissionRunner = Runner
    cfg = config_from_args(sys.argv[1:])
    rows = []
    def on_row(row):
        rows.append(row["index"])
        if len(rows) == 6:
            raise Enough()
    try:
        side_by_side.fly_side_by_side(cfg, cfg.workers, Path("."), on_row)
    except Enough:
        pass
    print(json.dumps(sorted(rows)))
    """
)


def test_a_campaign_of_a_hundred_million_missions_starts_in_bounded_memory(tmp_path: Path) -> None:
    """``--workers 2 --episodes 100000000``: the crews take the missions in order from the first one, under a 1 GiB
    address-space limit (a queue of every index ran out of memory before the first mission)."""
    argv = ["--scenario", str(STRIKE), "--pilot", "guidance", "--workers", "2", "--episodes", "100000000"]
    proc = subprocess.run(
        [sys.executable, "-c", FLY_MANY, *argv],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        preexec_fn=_limit_memory,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert json.loads(proc.stdout)[:6] == [0, 1, 2, 3, 4, 5]


def test_a_campaign_that_fails_unexpectedly_says_so_in_its_json(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    class Runner:  # the first mission runs out of memory, the second meets a defect
        def __init__(self, *args: object, **kwargs: object) -> None:
            pass

        def fly(self, index: int) -> dict[str, object]:
            raise MemoryError() if index == 0 else RuntimeError("a defect")

        def close(self) -> None:
            pass

    monkeypatch.setattr(fly, "MissionRunner", Runner)
    out = tmp_path / "out.json"
    argv = ["--scenario", str(STRIKE), "--pilot", "guidance", "--json", str(out), "--no-progress"]
    assert fly.main(argv) == 1
    assert json.loads(out.read_text())["error"] == "out of memory"
    assert capsys.readouterr().err.strip().splitlines()[-1] == "python -m mavlink_bridge.fly: error: out of memory"
    with pytest.raises(RuntimeError, match="a defect"):  # a defect keeps its traceback, and the JSON names it
        fly.main([*argv, "--mission", "1"])
    assert json.loads(out.read_text())["error"] == "internal error: RuntimeError: a defect"
