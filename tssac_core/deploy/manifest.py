"""The integrity manifest of a models directory: ``SHA256SUMS``, the SHA-256 of every file a loader reads.

The format is the one ``sha256sum`` writes and checks (``cd DIR && sha256sum -c SHA256SUMS``): one line per
file, ``<64 lowercase hex digits><two spaces><file name>``, sorted by name. The names are plain file names in
the manifest's own directory. Listed: ``config.json``, ``<role>.pt``, ``<role>.npz`` and ``<role>.onnx`` (whichever
exist); not the metrics, logs, plots or ``resume/``, which no loader reads and training keeps appending to. A finished
results row that is committed as a whole (a cross-check run: OmniSafe's ``actor.npz``, its checkpoint, configs and
logs) lists every file in its directory instead (``write --all``).

Who writes it: ``python -m tssac_core.train`` (``config.json`` when a run starts or resumes, each role's two
files when the role ships), ``python -m tssac_core.deploy.export``, the grid's ``--compact``, and
``python -m tssac_core.deploy.manifest write DIR``; every write replaces the file atomically.
Who checks it: every command that loads a team or an actor (:func:`check_models`), before it loads one.

It guards against accidental change (a bad copy, a disk error, an editor), not against an attacker: anyone who
can change a model file can change the manifest beside it. A directory without a manifest (a run trained
before manifests existed) is read with one warning line.

No torch: the companion imports it (through :func:`tssac_core.deploy.numpy_actor.load_actor`).
"""

from __future__ import annotations

import argparse
import functools
import logging
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from tssac_core.common.errors import CheckpointError
from tssac_core.common.files import replace_durably, sha256_file
from tssac_core.sim.scenario import ROLES

MANIFEST = "SHA256SUMS"
CONFIG = "config.json"
MODEL_SUFFIXES = (".pt", ".npz", ".onnx")

_LINE = re.compile(r"([0-9a-f]{64}) [ *](.+)")  # sha256sum's text (two spaces) and binary (" *") forms

logger = logging.getLogger(__name__)


def model_files(directory: Path) -> list[str]:
    """The files of ``directory`` a manifest lists: ``config.json`` and every ``<role>`` .pt, .npz and .onnx there."""
    names = [CONFIG] + [role.value + suffix for role in ROLES for suffix in MODEL_SUFFIXES]
    return sorted(name for name in names if (directory / name).is_file())


def all_files(directory: Path) -> list[str]:
    """Every regular file of ``directory`` but the manifest itself (``write --all``: a finished results row)."""
    skip = {MANIFEST, MANIFEST + ".tmp"}
    return sorted(p.name for p in directory.iterdir() if p.is_file() and p.name not in skip)


def read_manifest(directory: Path) -> dict[str, str] | None:
    """``{file name: sha256}`` of ``directory/SHA256SUMS``; None without one; CheckpointError for a line that is
    not ``<sha256>  <file name>``."""
    path = directory / MANIFEST
    if not path.is_file():
        return None
    entries: dict[str, str] = {}
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        match = _LINE.fullmatch(line)
        name = match.group(2) if match else ""
        if match is None or "/" in name or "\\" in name or name in (".", ".."):
            raise CheckpointError(f"{path}: line {number} is not '<sha256>  <file name>'")
        entries[name] = match.group(1)
    return entries


def write_manifest(directory: Path, entries: Mapping[str, str]) -> Path:
    """Replace ``directory/SHA256SUMS`` with ``entries`` atomically (a crash leaves the old manifest or the new)."""
    path = directory / MANIFEST
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text("".join(f"{digest}  {name}\n" for name, digest in sorted(entries.items())), encoding="utf-8")
    replace_durably(tmp, path)
    return path


def record(directory: Path, names: Iterable[str]) -> Path:
    """Hash the files ``names`` of ``directory`` as they are now and set their entries in its manifest (created if
    there is none; the other entries are kept). Called by whatever has just written those files."""
    entries = read_manifest(directory) or {}
    for name in names:
        entries[name] = sha256_file(directory / name)
    return write_manifest(directory, entries)


def problems(directory: Path, entries: Mapping[str, str], names: Iterable[str] | None = None) -> list[str]:
    """One line per listed file (of ``names`` only, if given) that is missing or differs from its entry (empty: all
    match)."""
    chosen = entries if names is None else {name: entries[name] for name in names if name in entries}
    found = []
    for name, digest in sorted(chosen.items()):
        path = directory / name
        if not path.is_file():
            found.append(f"{path}: listed in {directory / MANIFEST} but missing")
        elif sha256_file(path) != digest:
            found.append(f"{path}: its sha256 differs from {directory / MANIFEST} (changed after it was written)")
    return found


def check_recorded(directory: Path, names: Iterable[str]) -> None:
    """CheckpointError unless the manifest of ``directory`` lists ``names`` as they are now (nothing to check
    without a manifest): what training asks of a role it has shipped."""
    entries = read_manifest(directory)
    if entries is None:
        return
    for name in names:
        if name not in entries:
            raise CheckpointError(f"{directory / name}: not recorded in {directory / MANIFEST}")
        if sha256_file(directory / name) != entries[name]:
            raise CheckpointError(f"{directory / name}: its sha256 differs from {directory / MANIFEST}")


def check_models(directory: Path, reads: Iterable[str], every_entry: bool = True) -> str | None:
    """Before a command loads the files ``reads`` from ``directory``: every file its manifest lists (only those of
    ``reads`` if not ``every_entry``: a writer about to replace the others) is there and unchanged (CheckpointError
    naming the first that is not: one line, exit code 2 in every command line).
    Returns the warning to give (:func:`warn_once`) once the files have loaded, if some are read unchecked (no
    manifest, or not listed in it); None if every one is checked. (After loading, so that a file that does not load
    is still one line.)"""
    reads = list(reads)
    entries = read_manifest(directory)
    if entries is None:
        return (
            f"{directory} has no {MANIFEST}: its model files are read unchecked "
            f"(python -m tssac_core.deploy.manifest write {directory})"
        )
    found = problems(directory, entries, None if every_entry else reads)
    if found:
        raise CheckpointError(found[0])
    unlisted = [name for name in reads if name not in entries]
    return f"{', '.join(unlisted)}: not listed in {directory / MANIFEST}, read unchecked" if unlisted else None


def check_model_file(path: Path) -> str | None:
    """:func:`check_models` for a loader of one file (the companion's actor)."""
    return check_models(path.parent, [path.name])


@functools.cache
def warn_once(message: str | None) -> None:
    """Log ``message`` as a warning, once per process (a command may load a directory's files one by one)."""
    if message is not None:
        logger.warning(message)


def write_command(directory: Path, force: bool, every_file: bool = False) -> str:
    """``write DIR``: record the model files there now (``every_file``: every file there); refused if an existing
    manifest disagrees with them and not ``force`` (re-recording would bless a damaged file)."""
    if not directory.is_dir():
        names = []
    else:
        names = all_files(directory) if every_file else model_files(directory)
    if not names:
        wanted = "files" if every_file else "config.json, <role>.pt, <role>.npz or <role>.onnx"
        raise CheckpointError(f"{directory}: no {wanted} here")
    entries = read_manifest(directory)
    found = problems(directory, entries) if entries is not None else []
    if found and not force:
        raise CheckpointError(f"{found[0]}; --force records the files as they are now")
    path = write_manifest(directory, {name: sha256_file(directory / name) for name in names})
    return f"wrote {path} ({len(names)} files)"


def check_command(directory: Path) -> str:
    """``check DIR``: every listed file is there and unchanged (CheckpointError otherwise, also without a manifest)."""
    entries = read_manifest(directory)
    if entries is None:
        raise CheckpointError(f"{directory / MANIFEST}: not found")
    found = problems(directory, entries)
    if found:
        raise CheckpointError(found[0])
    return f"{directory}: {len(entries)} files match {MANIFEST}"


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m tssac_core.deploy.manifest",
        description=f"Write or check {MANIFEST} (sha256sum's format) of models directories.",
    )
    p.add_argument("action", choices=("write", "check"), help="write: record the files now there; check: compare")
    p.add_argument("dirs", nargs="+", type=Path, metavar="DIR", help="models or run directories")
    p.add_argument("--force", action="store_true", help="write: also over a manifest the files no longer match")
    p.add_argument(
        "--all", action="store_true", help="write: list every file of the directory (a finished results row)"
    )
    args = p.parse_args(argv)
    for directory in args.dirs:
        if args.action == "write":
            print(write_command(directory, args.force, args.all))
        else:
            print(check_command(directory))
    return 0


if __name__ == "__main__":
    from tssac_core.common.cli import run

    raise SystemExit(run(main))
