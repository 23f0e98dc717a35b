"""Ground stations driven headless in tests: MAVProxy's console through a pipe, and a free UDP port for one."""

from __future__ import annotations

import fcntl
import os
import select
import socket
import subprocess
import sys
import time
from pathlib import Path

MAVPROXY = Path(sys.executable).parent / "mavproxy.py"
"""MAVProxy's script (a dev dependency: pip install -e .[dev])."""


class MavProxyConsole:
    """MAVProxy's console through a pipe: lines with their arrival time since start."""

    def __init__(self, port: int, cwd: Path, master: str | None = None) -> None:
        self.t0 = time.monotonic()
        self.proc = subprocess.Popen(
            [sys.executable, str(MAVPROXY), f"--master={master or f'udpout:127.0.0.1:{port}'}", "--no-state"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            cwd=cwd,
        )
        assert self.proc.stdout is not None
        fcntl.fcntl(self.proc.stdout, fcntl.F_SETFL, os.O_NONBLOCK)
        self.lines: list[tuple[float, str]] = []
        self._partial = ""

    def wait_line(self, part: str, timeout_s: float) -> float | None:
        """Seconds since start at which a line containing ``part`` arrived (None: not within the timeout)."""
        assert self.proc.stdout is not None
        deadline = time.monotonic() + timeout_s
        while True:
            for t, line in self.lines:
                if part in line:
                    return t
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            if select.select([self.proc.stdout], [], [], min(remaining, 0.05))[0]:
                chunk = self.proc.stdout.read() or ""
                now = time.monotonic() - self.t0
                text = self._partial + chunk
                *done, self._partial = text.split("\n")
                self.lines += [(now, line) for line in done]

    def send(self, command: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()  # EOF ends MAVProxy's input loop
        try:
            self.proc.wait(3.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(3.0)


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])
