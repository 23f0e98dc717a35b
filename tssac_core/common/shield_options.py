"""The monitor's command-line options shared by ``fly``, the companion, ``evaluate`` and the benchmarks,
``--shield-adjust`` and ``--shield-route-edge-km``, and the reports' words for what it did."""

from __future__ import annotations

import math

from tssac_core.common.cli import UsageError

SHIELD_ADJUST_HELP = (
    "with --shield: when the pilot's action fails the monitor's check, fly the passing action nearest it (its turn "
    "rate or one of -1, -0.75 .. 1 of the limit, at its acceleration or braking) before the backup takes over "
    "(docs/runtime_assurance.md, 'Adjusted actions')"
)


SHIELD_ROUTE_EDGE_HELP = (
    "with --shield: the route a policy observes treats this band inside the area's edge as a hazard, so that the way "
    "round the radars it is shown leaves the monitor's backups their room at the geofence (default 0: the route it "
    "was trained on; docs/runtime_assurance.md, 'A route that leaves the backups room')"
)


def adjusted_text(fraction: float | None) -> str:
    """The report's words for the share of time under adjusted actions: ", 1.23% adjusted", or nothing when none
    flew."""
    return f", {fraction:.2%} adjusted" if fraction else ""


def held_text(fraction: float | None) -> str:
    """The report's words for the share of time a backup's lead held its line: ", 1.23% holding a line", or nothing
    when none did."""
    return f", {fraction:.2%} holding a line" if fraction else ""


def adjust_option(adjust: bool, shield: bool) -> bool:
    """``--shield-adjust``, checked: it changes the monitor, so it needs ``--shield`` (one :class:`UsageError` line)."""
    if adjust and not shield:
        raise UsageError("--shield-adjust changes what the monitor flies: it needs --shield")
    return adjust


def route_edge_option(km: float, shield: bool) -> float:
    """``--shield-route-edge-km``, checked and in metres: a finite width >= 0 that needs ``--shield`` (one
    :class:`UsageError` line)."""
    if not (math.isfinite(km) and km >= 0):
        raise UsageError(f"--shield-route-edge-km must be a finite width >= 0, got {km:g}")
    if km and not shield:
        raise UsageError("--shield-route-edge-km asks the pilot for the monitor's room: it needs --shield")
    return 1000.0 * km
