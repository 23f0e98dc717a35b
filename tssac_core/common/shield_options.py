"""The monitor's command-line option shared by ``fly``, the companion, ``evaluate`` and the benchmarks,
``--shield-adjust``, and the reports' words for what it did (its tuning's options:
:mod:`tssac_core.sim.shield_tuning`)."""

from __future__ import annotations

from tssac_core.common.cli import UsageError

SHIELD_ADJUST_HELP = (
    "with --shield: when the pilot's action fails the monitor's check, fly the passing action nearest it (its turn "
    "rate or one of -1, -0.75 .. 1 of the limit, at its acceleration or braking) before the backup takes over "
    "(docs/runtime_assurance.md, 'Adjusted actions')"
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
