"""A fork server: ``python -m MODULE ARGS`` started from an interpreter that has already imported MODULE's imports.

A companion's imports (numpy, pymavlink, filterpy with ``scipy.stats``) cost about 0.7-1 s of CPU, the world's about
0.2 s, and a campaign's crews start eight of them on two cores. :class:`ForkServer` starts one server process
(``python -m mavlink_bridge.processes.fork_server --socket-fd N MODULE ...``) that imports the modules it is given
once; each :meth:`ForkServer.start` then forks the server and runs the program in the fork exactly as ``python -m``
would (:func:`runpy.run_module` as ``__main__``, ``sys.argv`` set, ``SystemExit`` taken as the exit status), so what the
program does and prints is the same as a fresh interpreter's; only the imports are already done.

Each forked program is a child as :mod:`mavlink_bridge.processes.children` wants one: it leads a session of its own (a
terminal's Ctrl-C reaches only the parent, which stops it; it is stopped by process group), and it receives SIGTERM
when the server dies, as the server does when the thread of fly that started it ends, so nothing outlives fly. Its
standard input and output are pipes to fly (passed over the server's Unix socket) or empty, its standard error goes
to its log file. fly is not its parent, so the server reaps it and tells fly its exit status
(:class:`ForkedProcess` answers ``poll`` and ``wait`` like :class:`subprocess.Popen`).

The wire between fly and the server is a ``SOCK_SEQPACKET`` socket pair, one JSON object per packet: fly sends
``{"name", "module", "argv", "log", "stdin", "stdout"}`` with the pipe ends as ``SCM_RIGHTS``; the server answers
``{"started": PID}`` or ``{"error": "one line"}``, and later ``{"exited": PID, "returncode": RC}`` (RC negative: the
signal that killed it, as Popen says). The end of the socket ends the server: it stops its programs (SIGTERM, then
SIGKILL after a grace period) and exits.
"""

from __future__ import annotations

import argparse
import ctypes
import importlib
import json
import logging
import os
import runpy
import select
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
from collections.abc import Sequence
from pathlib import Path
from typing import IO, Any, NoReturn

from mavlink_bridge.processes.children import Child, ChildProcesses
from tssac_core.common.sessions import keep_nice_in_new_session

_log = logging.getLogger(__name__)

PROG = "python -m mavlink_bridge.processes.fork_server"
_MAX_PACKET = 1 << 16
_PR_SET_PDEATHSIG = 1
_PR_SET_NAME = 15
STOP_GRACE_S = 5.0
"""How long the server gives its programs after SIGTERM when it is told to end, before SIGKILL."""


AVAILABLE = sys.platform.startswith("linux")
"""The server needs Linux: ``PR_SET_PDEATHSIG`` ties each fork's life to the server's, and fly passes the pipes over an
``AF_UNIX`` ``SOCK_SEQPACKET`` socket. Elsewhere fly starts every process afresh."""


class ForkServerError(Exception):
    """The server could not start a program (or is gone); ``str()`` is one line."""


# ---------------------------------------------------------------------------------------------------- fly's side


class ForkedProcess:
    """A program the server forked: ``pid``, ``stdin`` / ``stdout`` (fly's ends of its pipes, or None), and
    ``poll`` / ``wait`` / ``returncode`` as :class:`subprocess.Popen` has them."""

    def __init__(
        self, server: ForkServer, pid: int, args: list[str], stdin: IO[bytes] | None, stdout: IO[bytes] | None
    ):
        self.server = server
        self.pid = pid
        self.args = args
        self.stdin = stdin
        self.stdout = stdout
        self.returncode: int | None = None

    def poll(self) -> int | None:
        if self.returncode is None:
            self.returncode = self.server.returncode(self.pid, 0.0)
        return self.returncode

    def send_signal(self, sig: int) -> None:
        """Signal the program (nothing once it has ended)."""
        if self.poll() is None:
            try:
                os.kill(self.pid, sig)
            except ProcessLookupError:
                pass

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)

    def wait(self, timeout: float | None = None) -> int:
        """The exit status; raises :class:`subprocess.TimeoutExpired` when it is still running after ``timeout``."""
        if self.returncode is None:
            self.returncode = self.server.returncode(self.pid, timeout)
            if self.returncode is None:
                raise subprocess.TimeoutExpired(self.args, timeout or 0.0)
        return self.returncode


class ForkServer:
    """fly's handle of one fork server (see the module docstring). Thread-safe: crews' threads start programs and
    the main thread may stop them."""

    def __init__(
        self, children: ChildProcesses, preload: Sequence[str], *, log_path: Path | None, env: dict[str, str]
    ) -> None:
        """Start the server as a child of ``children`` (its own session, dies with the calling thread); it imports
        ``preload`` before it forks anything."""
        self.children = children
        mine, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            argv = [
                sys.executable,
                "-m",
                "mavlink_bridge.processes.fork_server",
                "--socket-fd",
                str(theirs.fileno()),
                *preload,
            ]
            self.child = children.start("fork-server", argv, log_path=log_path, env=env, pass_fds=(theirs.fileno(),))
        except BaseException:
            mine.close()
            raise
        finally:
            theirs.close()
        self._sock = mine
        self._lock = threading.Lock()
        """Held to read or write the socket."""
        self._starting = threading.Lock()
        """Held from a request to its answer (answers come in the order of the requests)."""
        self._exited: dict[int, int] = {}
        self._started: list[dict[str, Any]] = []
        self._gone = False

    @property
    def alive(self) -> bool:
        return not self._gone and self.child.poll() is None

    def start(
        self,
        name: str,
        module: str,
        argv: Sequence[str],
        *,
        log_path: Path | None,
        stdin_pipe: bool = False,
        stdout_pipe: bool = False,
        timeout_s: float = 60.0,
    ) -> Child:
        """Fork ``python -m module argv`` as a child of the server's :class:`ChildProcesses` (stopped as its other
        children are); waits up to ``timeout_s`` for the server (for its imports, the first time)."""
        theirs: list[int] = []
        stdin: IO[bytes] | None = None
        stdout: IO[bytes] | None = None
        try:
            if stdin_pipe:
                r, w = os.pipe()
                theirs.append(r)
                stdin = open(w, "wb")
            if stdout_pipe:
                r, w = os.pipe()
                theirs.append(w)
                stdout = open(r, "rb")
            request = {
                "name": name,
                "module": module,
                "argv": list(argv),
                "log": None if log_path is None else str(log_path),
                "stdin": stdin_pipe,
                "stdout": stdout_pipe,
            }
            with self._starting:
                with self._lock:
                    try:
                        socket.send_fds(self._sock, [json.dumps(request).encode()], theirs)
                    except OSError as exc:
                        self._gone = True
                        raise ForkServerError(f"the fork server (pid {self.child.pid}) has ended ({exc})") from None
                reply = self._reply(timeout_s)
        except BaseException:
            for f in (stdin, stdout):
                if f is not None:
                    f.close()
            raise
        finally:
            for fd in theirs:
                _close(fd)
        process = ForkedProcess(self, int(reply["started"]), [module, *argv], stdin, stdout)
        return self.children.adopt(name, process, log_path)

    def returncode(self, pid: int, timeout_s: float | None) -> int | None:
        """``pid``'s exit status once the server has reaped it, waiting up to ``timeout_s`` (None: for ever)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            with self._lock:
                self._read(0.0)
                if pid in self._exited:
                    return self._exited[pid]
                gone = self._gone
                if gone:
                    status = _status_without_server(pid)
                    if status is not None:
                        return status
            remaining = 0.05 if deadline is None else min(0.05, deadline - time.monotonic())
            if remaining <= 0:
                return None
            if gone:
                # A socket at its end is always readable: waiting on it would spin, and a spinning parent starves
                # the very programs whose exit it waits for on a busy machine.
                time.sleep(min(remaining, 0.01))
            else:
                _wait_readable(self._sock, remaining)

    def close(self, grace_s: float = STOP_GRACE_S) -> None:
        """End the server (it stops what it still runs) and reap it."""
        with self._lock:
            if self._sock.fileno() >= 0:
                self._sock.close()
            self._gone = True
        try:
            self.child.process.wait(grace_s + 2.0)
        except subprocess.TimeoutExpired:
            pass  # the caller's ChildProcesses stops it

    def _reply(self, timeout_s: float) -> dict[str, Any]:
        deadline = time.monotonic() + timeout_s
        while True:
            with self._lock:
                self._read(0.0)
                if self._started:
                    reply = self._started.pop(0)
                    if "error" in reply:
                        raise ForkServerError(str(reply["error"]))
                    return reply
                if self._gone:
                    raise ForkServerError(f"the fork server (pid {self.child.pid}) ended before it answered")
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                self._gone = True  # its late answer would answer the next request: use a new server
                raise ForkServerError(f"the fork server (pid {self.child.pid}) did not answer within {timeout_s:g} s")
            _wait_readable(self._sock, min(remaining, 0.2))

    def _read(self, timeout_s: float) -> None:
        """Take every packet waiting (the caller holds the lock)."""
        while not self._gone:
            if not _wait_readable(self._sock, timeout_s):
                return
            try:
                data = self._sock.recv(_MAX_PACKET)
            except OSError:
                data = b""
            if not data:
                self._gone = True
                return
            message = json.loads(data)
            if "exited" in message:
                self._exited[int(message["exited"])] = int(message["returncode"])
            else:
                self._started.append(message)


def _wait_readable(sock: socket.socket, timeout_s: float) -> bool:
    try:
        ready, _, _ = select.select([sock], [], [], max(0.0, timeout_s))
    except (OSError, ValueError):  # closed
        return False
    return bool(ready)


def _status_without_server(pid: int) -> int | None:
    """A program's status once its server is gone: None while it runs, else -SIGTERM, the signal its server's
    death sent it (the status itself went to whoever reaped it, or nobody: a zombie counts as ended)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            state = fh.read().rsplit(b")", 1)[1].split()[0]
    except (OSError, IndexError):
        return -signal.SIGTERM
    return -signal.SIGTERM if state in (b"Z", b"X") else None


def _close(fd: int) -> None:
    try:
        os.close(fd)
    except OSError:
        pass


# ------------------------------------------------------------------------------------------------ the server


class _Server:
    """The server's loop: fork on request, reap and report, stop everything at the end of the socket."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.running: set[int] = set()
        self.wake_r, self.wake_w = os.pipe()
        os.set_blocking(self.wake_r, False)
        os.set_blocking(self.wake_w, False)
        self.stop_requested = False
        # The C library for the forks' prctl calls, loaded once here rather than in every fork
        self.libc = ctypes.CDLL(None, use_errno=True)

    def serve(self) -> None:
        signal.set_wakeup_fd(self.wake_w)
        signal.signal(signal.SIGCHLD, lambda _s, _f: None)
        signal.signal(signal.SIGTERM, self._on_stop)
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # fly stops the server; a terminal's Ctrl-C reaches fly only
        try:
            while not self.stop_requested:
                try:
                    ready, _, _ = select.select([self.sock.fileno(), self.wake_r], [], [])
                except InterruptedError:
                    continue
                if self.wake_r in ready:
                    while _read_some(self.wake_r):
                        pass
                    self._reap()
                if self.sock.fileno() in ready and not self._take_request():
                    break
        finally:
            self._stop_all()

    def _on_stop(self, _signum: int, _frame: object) -> None:
        self.stop_requested = True

    def _take_request(self) -> bool:
        """Serve one request; False at the end of the socket."""
        try:
            data, fds, _flags, _addr = socket.recv_fds(self.sock, _MAX_PACKET, 2)
        except OSError:
            return False
        if not data:
            return False
        try:
            request = json.loads(data)
            self._send({"started": self._fork(request, fds)})
        except (OSError, ValueError, KeyError, TypeError) as exc:
            self._send({"error": f"cannot start {str(data[:120], errors='replace')}: {exc}"})
        finally:
            for fd in fds:
                _close(fd)
        return True

    def _fork(self, request: dict[str, Any], fds: list[int]) -> int:
        module = str(request["module"])
        name = str(request["name"])
        argv = [str(a) for a in request["argv"]]
        fds = list(fds)
        stdin = fds.pop(0) if request["stdin"] else None
        stdout = fds.pop(0) if request["stdout"] else None
        log = None
        if request["log"] is not None:
            path = Path(request["log"])
            path.parent.mkdir(parents=True, exist_ok=True)
            log = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        settled_r, settled_w = os.pipe()
        try:
            sys.stdout.flush()
            sys.stderr.flush()
            pid = os.fork()
            if pid == 0:  # the program: never back into the server's loop
                try:
                    os.close(settled_r)
                    _run_program(self, name, module, argv, stdin, stdout, log, settled_w)
                finally:
                    os._exit(1)
            self.running.add(pid)
            os.close(settled_w)
            settled_w = -1
            os.read(settled_r, 1)  # the end of the pipe: it leads its session now (or has died), so fly may stop it
        finally:
            for fd in (log, settled_r, settled_w):
                if fd is not None and fd >= 0:
                    os.close(fd)
        return pid

    def _reap(self) -> None:
        while self.running:
            try:
                pid, status = os.waitpid(-1, os.WNOHANG)
            except ChildProcessError:
                self.running.clear()
                return
            if pid == 0:
                return
            self.running.discard(pid)
            self._send({"exited": pid, "returncode": os.waitstatus_to_exitcode(status)})

    def _send(self, message: dict[str, Any]) -> None:
        try:
            self.sock.send(json.dumps(message).encode())
        except OSError:  # fly is gone: its end of the socket reads as the end too
            self.stop_requested = True

    def _stop_all(self) -> None:
        """SIGTERM every running program's group, SIGKILL what is left after the grace period, reap all."""
        for sig, grace in ((signal.SIGTERM, STOP_GRACE_S), (signal.SIGKILL, STOP_GRACE_S)):
            for pid in list(self.running):
                try:
                    os.killpg(pid, sig)
                except (ProcessLookupError, PermissionError):
                    pass
            deadline = time.monotonic() + grace
            while self.running and time.monotonic() < deadline:
                self._reap()
                time.sleep(0.01)
            if not self.running:
                return


def _read_some(fd: int) -> bool:
    try:
        return bool(os.read(fd, 512))
    except BlockingIOError:
        return False


def _run_program(
    server: _Server,
    name: str,
    module: str,
    argv: list[str],
    stdin: int | None,
    stdout: int | None,
    log: int | None,
    settled: int,
) -> None:
    """In the fork: become the program, as ``python -m module argv`` would be, and exit with its status."""
    code = 1
    try:
        parent = os.getppid()
        server.sock.close()
        signal.set_wakeup_fd(-1)
        os.close(server.wake_r)
        os.close(server.wake_w)
        for sig in (signal.SIGCHLD, signal.SIGTERM):
            signal.signal(sig, signal.SIG_DFL)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        os.setsid()
        keep_nice_in_new_session()
        server.libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
        server.libc.prctl(_PR_SET_NAME, name.encode()[:15], 0, 0, 0)  # what ps and top show it as
        if os.getppid() != parent:  # the server died before the line above: so must we
            os._exit(128 + signal.SIGTERM)
        os.close(settled)  # the server answers fly now: this pid is a session and process group of its own
        null = os.open(os.devnull, os.O_RDWR)
        os.dup2(stdin if stdin is not None else null, 0)
        os.dup2(stdout if stdout is not None else (log if log is not None else null), 1)
        os.dup2(log if log is not None else null, 2)
        for fd in {null, stdin, stdout, log} - {None, 0, 1, 2}:
            assert fd is not None
            os.close(fd)
        sys.argv = [module, *argv]
        for entry in (module, f"{module}.__main__"):  # preloaded as a module: run afresh as __main__, as python -m does
            loaded = sys.modules.get(entry)
            if loaded is not None and not hasattr(loaded, "__path__"):
                del sys.modules[entry]
        try:
            runpy.run_module(module, run_name="__main__", alter_sys=True)
            code = 0
        except SystemExit as exc:
            code = _exit_code(exc.code)
        except BaseException:
            traceback.print_exc()
            code = 1
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        logging.shutdown()
        os._exit(code)


def _exit_code(code: object) -> int:
    """``sys.exit(code)``'s exit status, as the interpreter gives it."""
    if code is None:
        return 0
    if isinstance(code, int):
        return code & 0xFF
    print(code, file=sys.stderr)
    return 1


def main(argv: Sequence[str] | None = None) -> NoReturn:
    parser = argparse.ArgumentParser(prog=PROG, description="Fork programs from an interpreter that imported them.")
    parser.add_argument("--socket-fd", type=int, required=True, help="fly's end of the socket pair (inherited)")
    parser.add_argument("preload", nargs="*", help="modules to import before the first fork")
    args = parser.parse_args(argv)
    sock = socket.socket(fileno=args.socket_fd)
    for name in args.preload:
        importlib.import_module(name)
    _Server(sock).serve()
    sys.stderr.flush()
    os._exit(0)  # no teardown of what the preload imported: fly waits for this exit at the end of each run


if __name__ == "__main__":
    main()
