"""What the commands write, where a user points them (issue 61, item 5): ``--json`` to a named pipe or a device writes
in place and leaves it what it is, through the user's own links, atomically to a regular file, and never through a
link someone else planted; keys and logs are new files of ours (mode 0600 for keys), never a planted file or link;
a directory others can write is refused for logs (tssac_core.common.files)."""

from __future__ import annotations

import hashlib
import json
import os
import stat
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from mavlink_bridge.fly import cli as fly
from mavlink_bridge.fly.config import make_signing_key
from tssac_core.common.cli import write_json
from tssac_core.common.files import create_exclusively, private_directory, sha256_file

REPO = Path(__file__).resolve().parents[1]
STRIKE = REPO / "scenarios" / "strike.yaml"
OTHER_UID = 65534
"""Another user (nobody), for files and links someone else planted."""
DATA = {"success_rate": 1.0, "episodes": 1}

needs_root = pytest.mark.skipif(os.geteuid() != 0, reason="makes device nodes and files of another user")


def _read_fifo(path: Path, into: list[bytes]) -> threading.Thread:
    def read() -> None:
        with open(path, "rb") as fh:
            into.append(fh.read())

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    return reader


def test_json_to_a_named_pipe_is_written_in_place(tmp_path: Path) -> None:
    fifo = tmp_path / "results.fifo"
    os.mkfifo(fifo)
    got: list[bytes] = []
    reader = _read_fifo(fifo, got)
    write_json(fifo, DATA)
    reader.join(10)
    assert json.loads(got[0]) == DATA
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)  # still a pipe, not a file renamed over it


@needs_root
def test_json_to_a_character_device_is_written_in_place_and_a_block_device_is_refused(tmp_path: Path) -> None:
    null = tmp_path / "null"
    os.mknod(null, stat.S_IFCHR | 0o666, os.makedev(1, 3))  # /dev/null's numbers, here
    write_json(null, DATA)
    assert stat.S_ISCHR(os.lstat(null).st_mode)
    disk = tmp_path / "loop"
    os.mknod(disk, stat.S_IFBLK | 0o600, os.makedev(7, 200))
    with pytest.raises(OSError, match="not a regular file"):
        write_json(disk, DATA)
    assert stat.S_ISBLK(os.lstat(disk).st_mode)


def test_json_through_the_users_own_link_replaces_the_file_it_names(tmp_path: Path) -> None:
    real = tmp_path / "real.json"
    real.write_text("{}")
    real.chmod(0o640)
    link = tmp_path / "link.json"
    link.symlink_to(real.name)
    write_json(link, DATA)
    assert link.is_symlink() and json.loads(real.read_text()) == DATA
    assert stat.S_IMODE(real.stat().st_mode) == 0o640  # the file's mode kept
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.json", "real.json"]  # no temporary file left
    dangling = tmp_path / "new.json"
    dangling.symlink_to("made.json")
    write_json(dangling, DATA)
    assert json.loads((tmp_path / "made.json").read_text()) == DATA


@needs_root
def test_json_is_not_written_through_a_link_another_user_planted(tmp_path: Path) -> None:
    victim = tmp_path / "victim"
    victim.write_text("precious")
    planted = tmp_path / "out.json"
    planted.symlink_to(victim)
    os.lchown(planted, OTHER_UID, OTHER_UID)
    with pytest.raises(PermissionError, match="a link of another user"):
        write_json(planted, DATA)
    assert victim.read_text() == "precious" and planted.is_symlink()


def test_json_is_never_written_through_a_planted_temporary_name(tmp_path: Path) -> None:
    """The temporary file of an atomic write is a new file with a name nobody can guess, not ``NAME.tmp``."""
    victim = tmp_path / "victim"
    victim.write_text("precious")
    (tmp_path / "out.json.tmp").symlink_to(victim)
    write_json(tmp_path / "out.json", DATA)
    assert victim.read_text() == "precious" and json.loads((tmp_path / "out.json").read_text()) == DATA


def test_json_to_a_directory_is_one_clear_error(tmp_path: Path) -> None:
    with pytest.raises(IsADirectoryError):
        write_json(tmp_path, DATA)


def test_evaluate_json_to_a_named_pipe(tmp_path: Path) -> None:
    """A command end to end: ``evaluate --json FIFO`` writes its results into the pipe's reader."""
    fifo = tmp_path / "results.fifo"
    os.mkfifo(fifo)
    got: list[bytes] = []
    reader = _read_fifo(fifo, got)
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "tssac_core.evaluate",
            "--controller",
            "guidance",
            "--episodes",
            "1",
            "--json",
            str(fifo),
        ]
        + ["--scenario", str(STRIKE), "--no-progress"],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        timeout=300,
    )
    reader.join(10)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert json.loads(got[0])["episodes"] == 1 and stat.S_ISFIFO(os.lstat(fifo).st_mode)


@needs_root
def test_a_planted_key_or_link_never_becomes_the_runs_key(tmp_path: Path) -> None:
    """``fly --logs DIR``: a ``signing.key`` another user left readable by all, or a link under that name, is
    replaced by a new key of ours, mode 0600; the link's target is untouched."""
    planted = tmp_path / "signing.key"
    planted.write_bytes(b"k" * 32)
    planted.chmod(0o644)
    os.chown(planted, OTHER_UID, OTHER_UID)
    key = make_signing_key(tmp_path)
    st = os.lstat(key)
    assert stat.S_IMODE(st.st_mode) == 0o600 and st.st_uid == os.geteuid() and key.read_bytes() != b"k" * 32
    victim = tmp_path / "victim"
    victim.write_text("precious")
    key.unlink()
    key.symlink_to(victim)
    os.lchown(key, OTHER_UID, OTHER_UID)
    make_signing_key(tmp_path)
    assert victim.read_text() == "precious" and not key.is_symlink() and len(key.read_bytes()) == 32


def test_an_exclusive_file_replaces_what_is_there_without_following_it(tmp_path: Path) -> None:
    victim = tmp_path / "victim"
    victim.write_text("precious")
    log = tmp_path / "a.log"
    log.symlink_to(victim)
    with os.fdopen(create_exclusively(log), "w") as fh:
        fh.write("ours")
    assert victim.read_text() == "precious" and log.read_text() == "ours" and not log.is_symlink()


@needs_root
def test_a_logs_directory_others_could_plant_in_is_refused(tmp_path: Path) -> None:
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o777)  # anyone may add, remove and rename entries
    with pytest.raises(PermissionError, match="other users can write in this directory"):
        private_directory(shared, "--logs")
    shared.chmod(0o1777)  # the sticky bit: nobody touches an entry of ours
    assert private_directory(shared, "--logs") == shared
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    os.chown(theirs, OTHER_UID, OTHER_UID)
    with pytest.raises(PermissionError, match="a directory of another user"):
        private_directory(theirs, "--logs")
    planted = shared / "mission-000"
    planted.symlink_to(theirs)
    os.lchown(planted, OTHER_UID, OTHER_UID)
    with pytest.raises(PermissionError, match="a link of another user"):
        private_directory(planted, "--logs")


@needs_root
def test_fly_refuses_such_a_logs_directory_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o777)
    assert fly.main(["--scenario", str(STRIKE), "--pilot", "guidance", "--logs", str(shared), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "other users can write in this directory" in err[0], err
    assert list(shared.iterdir()) == []  # no key, no mission written there


def test_a_companions_tlog_is_a_new_file_never_a_planted_link(tmp_path: Path) -> None:
    from mavlink_bridge.link.connection import MavLink

    victim = tmp_path / "victim"
    victim.write_text("precious")
    tlog = tmp_path / "decoy.tlog"
    tlog.symlink_to(victim)
    with MavLink("udpout:127.0.0.1:9", tlog_path=tlog) as link:
        link.send_heartbeat()
    assert victim.read_text() == "precious" and not tlog.is_symlink() and tlog.stat().st_size > 0


def test_json_to_a_descriptor_redirected_to_a_file_lands_in_order(tmp_path: Path) -> None:
    """``--json /dev/stdout > out.txt``: the command's own lines, then the JSON, in the one file the shell opened.
    (``/dev/fd/1`` here: the same descriptor by the name whose replacement fails harmlessly, in /proc, where a
    command that replaced its ``--json`` path would replace the machine's /dev/stdout.)"""
    out = tmp_path / "out.txt"
    code = "from tssac_core.common.cli import write_json; print('before'); write_json('/dev/fd/1', {'a': 1})"
    with out.open("w") as fh:
        subprocess.run(
            [sys.executable, "-c", code + "; print('after')"],
            stdout=fh,
            check=True,
            cwd=REPO,
            env=dict(os.environ, PYTHONPATH=str(REPO)),
            timeout=60,
        )
    lines = out.read_text().splitlines()
    assert lines[0] == "before" and lines[-1] == "after" and json.loads("\n".join(lines[1:-1])) == {"a": 1}


def test_a_files_digest_is_sha256_of_all_its_bytes(tmp_path: Path) -> None:
    """The one digest the manifests, the actors' sources, the response files and fly's resume key use: all of a file
    larger than one read block, and an empty one."""
    data = os.urandom(3 * 65536 + 17)
    (tmp_path / "big").write_bytes(data)
    (tmp_path / "empty").write_bytes(b"")
    assert sha256_file(tmp_path / "big") == hashlib.sha256(data).hexdigest()
    assert sha256_file(str(tmp_path / "empty")) == hashlib.sha256(b"").hexdigest()
    assert sha256_file(tmp_path / "big") != hashlib.sha256(data[:-1]).hexdigest()
