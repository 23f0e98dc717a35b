"""OmniSafe 0.5.0's own Python environment, built once and kept: ``python benchmarks/omnisafe_env.py`` prints its
interpreter, building it first if it is not there yet.

OmniSafe 0.5.0 pins gymnasium 0.28.1, and this project needs gymnasium >= 1.0: the adapter
(tssac_core/train/omnisafe_env.py), the cross-check's OmniSafe side and their tests (tests/test_omnisafe_env.py,
tests/test_crosscheck_omnisafe.py, which the main environment skips) run in an environment of their own, built once
and reused. It is a virtual environment with torch 2.13.0 (CPU) and exactly the packages of
benchmarks/omnisafe-requirements.txt (``--no-deps``: no resolver, the same versions every time), installed without
byte-compiling (about a third of the time; the build's import check then leaves the bytecode of what OmniSafe imports,
`writing_bytecode`), and safety-gymnasium 1.0.0's dataclasses made valid for Python 3.11
(``np.array`` defaults become ``default_factory``). 1.4 GB; 1.4 min of CPU, 2.5 to 12 min of wall time here on a
machine shared with other builds and test runs (with byte-compiling: 2.3 min of CPU, 9 to 10 min).

Where: ``$TSSAC_OMNISAFE_VENV`` if set, else ``~/.cache/tssac/omnisafe-<key>`` (``$XDG_CACHE_HOME`` honoured), the key
a digest of the requirements, torch's pin, :data:`BUILD` and the Python version: a change to any builds a new one. A
build marks the environment finished (a file ``BUILT`` in it) once it imports omnisafe: an unfinished one is built
again from scratch, never used. Builds are serialised by a lock file, so two test processes build it once.
"""

from __future__ import annotations

import argparse
import fcntl
import hashlib
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from tssac_core.common.cli import command_description  # noqa: E402

REQUIREMENTS = HERE / "omnisafe-requirements.txt"
TORCH = "torch==2.13.0"
BUILD = 1
"""The build's steps; raised when they change (a new key: a new environment)."""
ENV_VARIABLE = "TSSAC_OMNISAFE_VENV"
# safety-gymnasium 1.0.0's assets give dataclass fields mutable numpy defaults, which Python 3.11 refuses.
ARRAY_DEFAULT = re.compile(r": np\.array = COLOR\['([a-z_]+)'\]")


class BuildFailed(RuntimeError):
    """The environment could not be built; ``str()`` is one line."""


def location() -> Path:
    """Where the environment is (or will be): module docstring."""
    if os.environ.get(ENV_VARIABLE):
        return Path(os.environ[ENV_VARIABLE]).expanduser().resolve()
    digest = hashlib.sha256()
    for part in (REQUIREMENTS.read_bytes(), TORCH.encode(), str(BUILD).encode(), sys.version.encode()):
        digest.update(part)
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return cache / "tssac" / f"omnisafe-{digest.hexdigest()[:12]}"


def python_of(venv: Path) -> Path:
    return venv / "bin" / "python"


def built(venv: Path) -> bool:
    """Whether ``venv`` is a finished build (module docstring)."""
    return (venv / "BUILT").is_file() and python_of(venv).is_file()


def omnisafe_python(venv: Path | None = None) -> Path:
    """The environment's interpreter, built first if it is not there (module docstring); BuildFailed otherwise."""
    venv = venv or location()
    if built(venv):
        return python_of(venv)
    venv.parent.mkdir(parents=True, exist_ok=True)
    with open(venv.parent / f".{venv.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another process may be building it
        if not built(venv):
            build(venv)
    return python_of(venv)


def build(venv: Path) -> None:
    """Build the environment in ``venv`` (anything there first removed: an unfinished build), then mark it finished.
    In place, not renamed into place: a virtual environment's scripts name its path."""
    work = venv
    shutil.rmtree(work, ignore_errors=True)
    pip = [str(python_of(work)), "-m", "pip", "install", "-q", "--no-compile", "--disable-pip-version-check"]
    steps = [
        [sys.executable, "-m", "venv", str(work)],
        [*pip, TORCH],
        [*pip, "--no-deps", "-r", str(REQUIREMENTS)],
    ]
    for step in steps:
        done = subprocess.run(step, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if done.returncode != 0:
            errors = [line for line in done.stderr.splitlines() if "ERROR" in line] or done.stderr.splitlines()[-1:]
            raise BuildFailed(f"building OmniSafe's environment in {work}: {' '.join(step[:4])} ...: {errors[:1]}")
    patch_dataclasses(work)
    check = subprocess.run(
        [str(python_of(work)), "-c", "import omnisafe, safety_gymnasium; print(omnisafe.__version__)"],
        capture_output=True,
        text=True,
        env=writing_bytecode(),  # the check's imports leave their bytecode: the tests' imports do not compile again
    )
    if check.returncode != 0 or check.stdout.strip() != "0.5.0":
        last = (check.stderr.strip().splitlines() or ["no output"])[-1]
        raise BuildFailed(f"OmniSafe's environment in {work} does not import omnisafe 0.5.0: {last}")
    (work / "BUILT").write_text(f"omnisafe 0.5.0, {TORCH}, build {BUILD}\n")


def writing_bytecode() -> dict[str, str]:
    """The environment with bytecode writing on: a machine may set PYTHONDONTWRITEBYTECODE, and then every process
    that imports torch and OmniSafe from this environment (built without byte-compiling) compiles them again (about
    17 s of CPU here)."""
    return {key: value for key, value in os.environ.items() if key != "PYTHONDONTWRITEBYTECODE"}


def patch_dataclasses(venv: Path) -> int:
    """safety-gymnasium's ``field: np.array = COLOR['x']`` as ``field(default_factory=...)``; returns the files
    changed."""
    found = subprocess.run(
        [str(python_of(venv)), "-c", "import importlib.util as u; print(u.find_spec('safety_gymnasium').origin)"],
        capture_output=True,
        text=True,
        check=True,
    )
    changed = 0
    for path in sorted(Path(found.stdout.strip()).parent.glob("assets/**/*.py")):
        text = path.read_text()
        fixed = ARRAY_DEFAULT.sub(r": np.array = field(default_factory=lambda: COLOR['\1'])", text)
        if fixed != text:
            fixed = re.sub(
                r"^from dataclasses import dataclass$", "from dataclasses import dataclass, field", fixed, flags=re.M
            )
            path.write_text(fixed)
            changed += 1
    return changed


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python benchmarks/omnisafe_env.py", description=command_description(__doc__))
    p.add_argument("--venv", type=Path, help=f"where (default: ${ENV_VARIABLE}, else ~/.cache/tssac/omnisafe-<key>)")
    args = p.parse_args(argv)
    try:
        print(omnisafe_python(args.venv.resolve() if args.venv else None))
    except BuildFailed as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
