"""The models' integrity manifest (SHA256SUMS): written by training and export, checked by every command that loads
models; a file changed by one byte, or a listed file missing, is one line and exit code 2."""

from __future__ import annotations

import logging
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from tiny_training import tiny_args

from mavlink_bridge.companion.cli import main as companion_main
from mavlink_bridge.fly.cli import main as fly_main
from tssac_core.common.cli import run
from tssac_core.common.errors import CheckpointError
from tssac_core.deploy.export import main as export_main
from tssac_core.deploy.manifest import (
    MANIFEST,
    all_files,
    model_files,
    problems,
    read_manifest,
    record,
    write_manifest,
)
from tssac_core.deploy.manifest import main as manifest_main
from tssac_core.deploy.numpy_actor import load_actor
from tssac_core.deploy.policy import load_team
from tssac_core.evaluate import main as evaluate_main
from tssac_core.train.cli import main as train_main
from tssac_core.train.rundir import shipped

REPO = Path(__file__).resolve().parent.parent
SHIPPED = REPO / "models" / "tssac"
STRIKE = REPO / "scenarios" / "strike.yaml"
FILES = ["config.json", *(f"{role}{suffix}" for role in ("decoy", "detect", "strike") for suffix in (".pt", ".npz"))]


@pytest.fixture()
def models(tmp_path: Path) -> Path:
    """A copy of the shipped team's loadable files, with a manifest written by the command."""
    d = tmp_path / "models"
    d.mkdir()
    for name in FILES:
        shutil.copy(SHIPPED / name, d / name)
    assert manifest_main(["write", str(d)]) == 0
    return d


def flip_byte(path: Path) -> None:
    """Change one byte in the middle of the file (a .pt, .npz or .json that may well still load)."""
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01
    path.write_bytes(bytes(data))


def one_error_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    return lines[0]


def test_round_trip_in_sha256sum_format(models: Path, capsys):
    entries = read_manifest(models)
    assert entries is not None and sorted(entries) == sorted(FILES)
    lines = (models / MANIFEST).read_text().splitlines()
    assert [ln.split("  ")[1] for ln in lines] == sorted(FILES) and all(len(ln.split("  ")[0]) == 64 for ln in lines)
    assert run(manifest_main, ["check", str(models)]) == 0
    assert "7 files match" in capsys.readouterr().out
    if shutil.which("sha256sum"):  # users can check it without the project
        ok = subprocess.run(["sha256sum", "-c", MANIFEST], cwd=models, capture_output=True, text=True)
        assert ok.returncode == 0, ok.stdout + ok.stderr
    write_manifest(models, entries)  # rewriting the same entries gives the same bytes
    assert (models / MANIFEST).read_text().splitlines() == lines
    assert not (models / (MANIFEST + ".tmp")).exists()


def test_check_refuses_a_changed_file_and_a_malformed_manifest(models: Path, capsys):
    flip_byte(models / "strike.npz")
    assert run(manifest_main, ["check", str(models)]) == 2
    assert "strike.npz: its sha256 differs" in one_error_line(capsys.readouterr().err)
    assert run(manifest_main, ["write", str(models)]) == 2  # writing would bless the changed file
    assert "--force" in one_error_line(capsys.readouterr().err)
    assert run(manifest_main, ["write", "--force", str(models)]) == 0
    assert run(manifest_main, ["check", str(models)]) == 0
    (models / MANIFEST).write_text("not a digest  decoy.pt\n")
    assert run(manifest_main, ["check", str(models)]) == 2
    assert "line 1 is not '<sha256>  <file name>'" in one_error_line(capsys.readouterr().err)
    (models / MANIFEST).unlink()
    assert run(manifest_main, ["check", str(models)]) == 2
    capsys.readouterr()


def test_the_command_line_refuses_in_one_line():
    d = REPO / "models" / "tssac"
    proc = subprocess.run(
        [sys.executable, "-m", "tssac_core.deploy.manifest", "check", str(d / "nothing-here")],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=60,
    )
    assert proc.returncode == 2 and proc.stderr.startswith("error: ") and len(proc.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("name", ["decoy.pt", "strike.npz", "config.json"])
def test_evaluate_refuses_a_file_changed_by_one_byte(models: Path, capsys, name: str):
    flip_byte(models / name)
    assert run(evaluate_main, ["--models", str(models), "--episodes", "1", "--no-progress"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert line.startswith(f"error: {models / name}: its sha256 differs from {models / MANIFEST}"), line


def test_evaluate_refuses_a_missing_listed_file(models: Path, capsys):
    (models / "detect.npz").unlink()
    assert run(evaluate_main, ["--models", str(models), "--episodes", "1", "--no-progress"]) == 2
    assert f"{models / 'detect.npz'}: listed in" in one_error_line(capsys.readouterr().err)
    with pytest.raises(CheckpointError, match="detect.npz: listed in .* but missing"):
        load_team(models)


@pytest.mark.parametrize("name", ["detect.pt", "decoy.npz", "config.json"])
def test_the_companions_actor_loader_refuses_a_changed_file(models: Path, name: str):
    load_actor(models / "decoy.npz", "decoy")  # untouched: loads
    flip_byte(models / name)
    with pytest.raises(CheckpointError, match=f"{name}: its sha256 differs"):
        load_actor(models / "decoy.npz", "decoy")
    with pytest.raises(CheckpointError, match=f"{name}: its sha256 differs"):
        load_actor(models / "decoy.pt", "decoy")


def test_the_companion_refuses_a_changed_actor_in_one_line(models: Path, capsys):
    flip_byte(models / "decoy.npz")
    argv = ["--connect", "udpout:127.0.0.1:9", "--role", "decoy", "--model", str(models / "decoy.npz")]
    assert companion_main([*argv, "--scenario", str(STRIKE), "--timeout-s", "2"]) == 2
    assert "decoy.npz: its sha256 differs" in one_error_line(capsys.readouterr().err)


@pytest.mark.parametrize("name", ["strike.pt", "detect.npz", "config.json"])
def test_fly_refuses_a_changed_file_before_flying(models: Path, capsys, name: str):
    flip_byte(models / name)
    assert fly_main(["--scenario", str(STRIKE), "--models", str(models), "--no-progress"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert f"{models / name}: its sha256 differs" in line and "--pilot guidance" not in line, line


def test_a_directory_without_manifest_loads_with_one_warning(models: Path, caplog):
    (models / MANIFEST).unlink()
    with caplog.at_level(logging.WARNING, logger="tssac_core.deploy.manifest"):
        load_actor(models / "detect.npz", "detect")
        load_team(models)
    warnings = [r.getMessage() for r in caplog.records if r.name == "tssac_core.deploy.manifest"]
    assert len(warnings) == 1 and f"{models} has no {MANIFEST}" in warnings[0], warnings


def test_training_writes_a_manifest_and_export_updates_it(tmp_path: Path, capsys):
    out = tmp_path / "run"
    assert train_main([*tiny_args(), "--seed", "4", "--out", str(out)]) == 0
    entries = read_manifest(out)
    assert entries is not None and sorted(entries) == ["config.json", "decoy.npz", "decoy.pt"]
    assert run(manifest_main, ["check", str(out)]) == 0
    assert shipped(out, "decoy")

    before = (out / MANIFEST).read_text()
    (out / "decoy.npz").unlink()  # an actor exported again: the command records the new file
    assert run(export_main, [str(out)]) == 0
    assert run(manifest_main, ["check", str(out)]) == 0
    assert (out / MANIFEST).read_text() == before  # the same actor, byte for byte
    flip_byte(out / "decoy.pt")  # export refuses a changed checkpoint rather than record it
    assert run(export_main, [str(out)]) == 2
    assert "decoy.pt: its sha256 differs" in one_error_line(capsys.readouterr().err)
    assert not shipped(out, "decoy")  # a resume would ship the role again rather than keep the changed file


def test_a_kill_before_the_manifest_is_written_ships_the_role_again(tmp_path: Path):
    out = tmp_path / "run"
    assert train_main([*tiny_args(), "--seed", "5", "--out", str(out)]) == 0
    entries = read_manifest(out)
    assert entries is not None
    write_manifest(out, {"config.json": entries["config.json"]})  # killed between the export and the record
    assert not shipped(out, "decoy")
    assert train_main(["--out", str(out), "--resume", "--no-progress"]) == 0
    assert read_manifest(out) == entries  # the same role shipped again, recorded this time

    (out / MANIFEST).unlink()  # a run from before manifests: resuming records what it has, retrains nothing
    pt_bytes = (out / "decoy.pt").read_bytes()
    assert train_main(["--out", str(out), "--resume", "--no-progress"]) == 0
    assert read_manifest(out) == entries and (out / "decoy.pt").read_bytes() == pt_bytes


def test_record_keeps_the_other_entries(models: Path):
    entries = read_manifest(models)
    assert entries is not None
    (models / "config.json").write_text("{}\n")
    record(models, ["config.json"])
    updated = read_manifest(models)
    assert updated is not None and updated.pop("config.json") != entries.pop("config.json") and updated == entries


def test_write_all_lists_every_file_of_a_results_row_and_check_guards_each(tmp_path: Path, capsys):
    row = tmp_path / "omnisafe-cpo-seed0"  # a cross-check row: OmniSafe's actor, no <role> file
    row.mkdir()
    (row / "actor.npz").write_bytes(b"weights")
    (row / "progress.csv").write_text("epoch,return\n1,-300\n")
    (row / "config.json").write_text("{}\n")
    (row / "resume").mkdir()  # directories are not listed
    assert run(manifest_main, ["write", str(row)]) == 0  # without --all: the loader's files only
    assert sorted(read_manifest(row) or {}) == ["config.json"]
    assert run(manifest_main, ["write", "--all", str(row)]) == 0
    assert sorted(read_manifest(row) or {}) == ["actor.npz", "config.json", "progress.csv"] == all_files(row)
    assert run(manifest_main, ["check", str(row)]) == 0
    capsys.readouterr()
    flip_byte(row / "progress.csv")
    assert run(manifest_main, ["check", str(row)]) == 2
    assert "progress.csv: its sha256 differs" in one_error_line(capsys.readouterr().err)
    empty = tmp_path / "empty"
    empty.mkdir()
    assert run(manifest_main, ["write", "--all", str(empty)]) == 2
    assert "no files here" in one_error_line(capsys.readouterr().err)


def test_every_committed_models_directory_has_a_manifest_that_matches():
    """What the repository ships (models/, results/): any directory holding an actor can be checked, and is intact."""
    actors = [p for top in ("models", "results") for p in (REPO / top).rglob("*") if p.suffix in (".pt", ".npz")]
    dirs = sorted({p.parent for p in actors})
    assert REPO / "models" / "tssac" in dirs
    for d in dirs:
        entries = read_manifest(d)
        assert entries is not None, f"{d}: no {MANIFEST} (python -m tssac_core.deploy.manifest write {d})"
        assert not problems(d, entries), problems(d, entries)
        assert sorted(entries) in (model_files(d), all_files(d)), d  # a models directory, or a whole results row
        assert {p.name for p in d.iterdir() if p.suffix in (".pt", ".npz")} <= set(entries), d
