"""How the runtime-assurance monitor hands control back and what it asks the pilot to be shown
(:mod:`tssac_core.sim.pilot_view`), with the command-line options shared by ``fly``, the companion, ``evaluate`` and
the benchmarks (``--shield-release-m``, ``--shield-release-decisions``, ``--shield-radar-view-km``,
``--shield-route-edge-km``). None of it enters the guarantee: every action the monitor accepts and every backup it
flies earns it on its own (docs/runtime_assurance.md, "Giving the team its way back")."""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass

from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.common.cli import UsageError


@dataclass(frozen=True)
class ShieldTuning:
    """How the monitor hands control back and what it asks the pilot to be shown (``--shield-release-m``,
    ``--shield-release-decisions``, ``--shield-radar-view-km``, ``--shield-route-edge-km``): none of it enters the
    guarantee, which every accepted action and backup earns on its own (docs/runtime_assurance.md, 'Giving the team
    its way back')."""

    route_edge_m: float = 0.0
    radar_view_m: float = 0.0
    release_m: float = ShieldConfig.release_margin_m
    release_decisions: int = ShieldConfig.release_decisions

    def config(self, adjust: bool = False, margin_m: float = ShieldConfig.margin_m) -> ShieldConfig:
        """The monitor with these settings."""
        return ShieldConfig(
            margin_m=margin_m,
            adjust=adjust,
            route_edge_margin_m=self.route_edge_m,
            radar_view_margin_m=self.radar_view_m,
            release_margin_m=self.release_m,
            release_decisions=self.release_decisions,
        )


def add_tuning_options(g: argparse._ActionsContainer) -> None:
    """The four options: ``--shield-release-m``, ``--shield-release-decisions``, ``--shield-radar-view-km``,
    ``--shield-route-edge-km``."""
    g.add_argument(
        "--shield-release-m",
        type=float,
        default=ShieldConfig.release_margin_m,
        metavar="M",
        help="with --shield: the clearance on top of the margin that the policy's action needs, while a backup flies, "
        f"to take control back (default {ShieldConfig.release_margin_m:g})",
    )
    g.add_argument(
        "--shield-release-decisions",
        type=int,
        default=ShieldConfig.release_decisions,
        metavar="N",
        help="with --shield: consecutive decisions it needs that clearance for (default "
        f"{ShieldConfig.release_decisions})",
    )
    g.add_argument(
        "--shield-radar-view-km",
        type=float,
        default=0.0,
        metavar="KM",
        help="with --shield: the pilot is shown every radar this much larger than it is, so that it keeps the "
        "backups' room from the radars itself (default 0: as they are)",
    )
    g.add_argument(
        "--shield-route-edge-km",
        type=float,
        default=0.0,
        metavar="KM",
        help="with --shield: the route a policy observes treats this band inside the area's edge as a hazard, so that "
        "the way round the radars it is shown leaves the backups their room at the geofence (default 0: the route it "
        "was trained on)",
    )


def tuning_option(args: argparse.Namespace, shield: bool) -> ShieldTuning:
    """The tuning the options ask for, checked: finite and >= 0 (a count >= 1), and only with ``--shield`` (one
    :class:`UsageError` line)."""
    for flag in ("--shield-route-edge-km", "--shield-radar-view-km", "--shield-release-m"):
        value = getattr(args, flag[2:].replace("-", "_"))
        if not (math.isfinite(value) and value >= 0):
            raise UsageError(f"{flag} must be a finite number >= 0, got {value:g}")
    if args.shield_release_decisions < 1:
        raise UsageError(f"--shield-release-decisions must be >= 1, got {args.shield_release_decisions}")
    tuning = ShieldTuning(
        route_edge_m=1000.0 * args.shield_route_edge_km,
        radar_view_m=1000.0 * args.shield_radar_view_km,
        release_m=args.shield_release_m,
        release_decisions=args.shield_release_decisions,
    )
    if tuning != ShieldTuning() and not shield:
        raise UsageError(
            "the --shield-release-*, --shield-radar-view-km and --shield-route-edge-km options tune the "
            "monitor: they need --shield"
        )
    return tuning


def tuning_argv(tuning: ShieldTuning) -> list[str]:
    """The options that ask for ``tuning`` (none for the default), for a command started with them."""
    if tuning == ShieldTuning():
        return []
    return [
        "--shield-route-edge-km",
        repr(tuning.route_edge_m / 1000.0),
        "--shield-radar-view-km",
        repr(tuning.radar_view_m / 1000.0),
        "--shield-release-m",
        repr(tuning.release_m),
        "--shield-release-decisions",
        str(tuning.release_decisions),
    ]
