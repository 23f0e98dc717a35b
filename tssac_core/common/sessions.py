"""A process's nice value kept when it starts a session of its own.

Linux's autogroup scheduling (sched(7); on by default in most distributions' kernels) gives each session a scheduling
group of its own, weighted by the group's nice value, and a new group starts at 0 whatever the nice value of the
process that made it. The project's workers leave their parent's session so that a stop reaches their whole process
group (the fork server's worlds and companions, fly's children, the experiments' training jobs), so a campaign started
with ``nice -n 19`` competed with the user's shell as an equal: here, a CPU-bound command beside such a campaign got 45%
of one core of two. After ``setsid`` each of them now gives its new group its own nice value.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

AUTOGROUP = Path("/proc/self/autogroup")
"""The calling process's autogroup: reads as ``/autogroup-N nice K``; writing a number sets K (sched(7))."""


def keep_nice_in_new_session(autogroup: Path = AUTOGROUP) -> None:
    """Set the (new) session's autogroup nice value to this process's own, if that is above 0. Nothing where the
    kernel has no autogroups or the process runs at nice 0 or below (raising a group's priority needs privileges).
    Safe as a ``preexec_fn`` and right after ``os.setsid()``."""
    nice = os.getpriority(os.PRIO_PROCESS, 0)
    if nice <= 0:
        return
    try:
        autogroup.write_text(str(nice))
    except OSError:
        pass


def in_new_session(then: Callable[[], None] | None = None) -> Callable[[], None]:
    """A ``preexec_fn`` for a child started with ``start_new_session=True``: :func:`keep_nice_in_new_session` in the
    child's new session, then ``then``."""

    def preexec() -> None:
        keep_nice_in_new_session()
        if then is not None:
            then()

    return preexec
