"""Child processes that must never outlive their parent: own process groups, terminate then kill.

:class:`ChildProcesses` starts each child in its own session (so a Ctrl-C in the terminal reaches
only the parent, which then stops the children in order), asks Linux to send it SIGTERM if the
parent dies without cleaning up (``PR_SET_PDEATHSIG``, so even a ``kill -9`` of the parent leaves
no orphan), and stops children by process group: SIGTERM, a grace period, then SIGKILL, then
``wait()`` so that no zombie is left either. :meth:`ChildProcesses.stop_all` is idempotent and
registered with ``atexit``. A program started in its own session by someone else, a fork server's
(:mod:`mavlink_bridge.processes.fork_server`), is adopted (:meth:`ChildProcesses.adopt`) and stopped the same way.
"""

from __future__ import annotations

import atexit
import ctypes
import ctypes.util
import functools
import logging
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Protocol

from tssac_core.common.sessions import in_new_session

_log = logging.getLogger(__name__)

_PR_SET_PDEATHSIG = 1


@functools.cache
def _libc() -> ctypes.CDLL | None:
    """The C library, for ``prctl`` (Linux; None elsewhere or when it cannot be loaded). Loaded in the parent, once:
    finding it runs ``ldconfig``, which a child between fork and exec must not (nor anything that takes a lock
    another thread of the parent may hold)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    except OSError:
        return None


def _die_with_parent(libc: ctypes.CDLL) -> Callable[[], None]:
    """A preexec_fn: SIGTERM this child when the parent thread that started it ends (Linux's parent-death signal
    follows the thread; fly's threads stop their children before they end)."""

    def preexec() -> None:
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)

    return preexec


class ProcessHandle(Protocol):
    """What a parent holds of a running program: a :class:`subprocess.Popen`, or a
    :class:`mavlink_bridge.processes.fork_server.ForkedProcess`."""

    @property
    def pid(self) -> int: ...

    @property
    def stdin(self) -> IO[bytes] | None: ...

    @property
    def stdout(self) -> IO[bytes] | None: ...

    def poll(self) -> int | None: ...

    def wait(self, timeout: float | None = None) -> int:
        """The exit status; raises :class:`subprocess.TimeoutExpired` after ``timeout`` seconds."""
        ...


@dataclass
class Child:
    """One started child process."""

    name: str
    process: ProcessHandle
    log_path: Path | None

    @property
    def pid(self) -> int:
        return self.process.pid

    def poll(self) -> int | None:
        return self.process.poll()


class ChildProcesses:
    """The children one parent started (see the module docstring)."""

    def __init__(self, grace_s: float = 5.0) -> None:
        self.grace_s = grace_s
        self.children: list[Child] = []
        atexit.register(self.stop_all)

    def start(
        self,
        name: str,
        argv: Sequence[str],
        *,
        log_path: Path | None = None,
        stdout_pipe: bool = False,
        stdin_pipe: bool = False,
        cwd: Path | None = None,
        env: dict[str, str] | None = None,
        pass_fds: Sequence[int] = (),
    ) -> Child:
        """Start ``argv`` in a new session; stderr (and stdout unless piped) go to ``log_path``; stdin is piped
        (``stdin_pipe``) or empty; ``pass_fds`` stay open in the child."""
        libc = _libc()
        log: IO[bytes] | None = None
        if log_path is not None:
            log_path.parent.mkdir(parents=True, exist_ok=True)
            log = open(log_path, "wb")
        try:
            proc = subprocess.Popen(
                list(argv),
                stdin=subprocess.PIPE if stdin_pipe else subprocess.DEVNULL,
                stdout=subprocess.PIPE if stdout_pipe else (log if log is not None else subprocess.DEVNULL),
                stderr=log if log is not None else subprocess.DEVNULL,
                cwd=cwd,
                env=env,
                start_new_session=True,
                pass_fds=tuple(pass_fds),
                preexec_fn=in_new_session(None if libc is None else _die_with_parent(libc)),
            )
        finally:
            if log is not None:
                log.close()  # the child holds its own descriptor
        _log.debug("started %s (pid %d): %s", name, proc.pid, " ".join(argv))
        return self.adopt(name, proc, log_path)

    def adopt(self, name: str, process: ProcessHandle, log_path: Path | None) -> Child:
        """Take a program started elsewhere (in its own session, as :meth:`start` starts one) into the children."""
        child = Child(name, process, log_path)
        self.children.append(child)
        return child

    def alive(self) -> list[Child]:
        return [c for c in self.children if c.poll() is None]

    def stop(self, children: Sequence[Child], grace_s: float | None = None) -> None:
        """SIGTERM each running child's process group, wait up to ``grace_s``, SIGKILL what is left, reap all.

        A child that already exited was reaped by ``poll()``: its group id is not signalled any more,
        since it may have been reused (our children start no processes of their own).
        """
        grace = self.grace_s if grace_s is None else grace_s
        running = [c for c in children if c.poll() is None]
        for c in running:
            _signal_group(c, signal.SIGTERM)
        deadline = time.monotonic() + grace
        for c in running:
            try:
                c.process.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                pass
        for c in running:
            if c.poll() is None:
                _log.warning("%s (pid %d) did not stop within %.1f s: killing it", c.name, c.pid, grace)
                _signal_group(c, signal.SIGKILL)
        for c in running:
            try:
                c.process.wait(grace)
            except subprocess.TimeoutExpired:
                _log.error("%s (pid %d) survived SIGKILL", c.name, c.pid)
        for c in children:
            for pipe in (c.process.stdout, c.process.stdin):
                if pipe is not None and not pipe.closed:
                    try:
                        pipe.close()
                    except OSError:  # stdin of a child that died: the unwritten bytes are lost with it
                        pass

    def stop_all(self, grace_s: float | None = None) -> None:
        """Stop every child ever started (idempotent)."""
        if self.children:
            self.stop(self.children, grace_s)

    def forget_finished(self) -> None:
        """Drop reaped children from the list (between missions)."""
        self.children = [c for c in self.children if c.poll() is None]


def _signal_group(child: Child, sig: int) -> None:
    try:
        os.killpg(child.pid, sig)  # the child leads its own group (start_new_session)
    except ProcessLookupError:
        pass
    except PermissionError as exc:
        _log.error("cannot signal %s (pid %d): %s", child.name, child.pid, exc)
