"""The mission's map drawn with matplotlib into given axes: what the mission figures, the film and the env's own
frames (:meth:`tssac_core.sim.env.UavRoleEnv.render`) share. matplotlib is imported only when something is drawn, so
that importing the world stays light; the callers choose the backend (Agg for files and arrays)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Literal, TypedDict

from tssac_core.sim.scenario import Layout

ROLE_COLOURS = {"decoy": "tab:blue", "detect": "tab:green", "strike": "black"}


class LegendPlacement(TypedDict):
    """Keyword arguments of matplotlib's ``Axes.legend`` that place it."""

    fontsize: int
    loc: Literal["upper left"]
    bbox_to_anchor: tuple[float, float]
    borderaxespad: float


LEGEND_BESIDE: LegendPlacement = {
    "fontsize": 7,
    "loc": "upper left",
    "bbox_to_anchor": (1.02, 1.0),
    "borderaxespad": 0.0,
}
"""The mission figures' legend: beside the map, where it hides no track."""


def ring_labels(ranges_km: tuple[float, float, float, float]) -> tuple[str, str, str, str]:
    """The legend's words for the paper's R1-R4 (Table 1), innermost first."""
    r1, r2, r3, r4 = ranges_km
    return (
        f"strike UAV can launch within ({r1:g} km)",
        f"detect UAV identifies the target within ({r2:g} km)",
        f"SAM can fire within ({r3:g} km)",
        f"SAM radar sees within ({r4:g} km)",
    )


def draw_layout(ax: Any, layout_: object, ranges_km: tuple[float, float, float, float], area_km: float) -> None:
    """What does not move in a mission: the radar sites and their coverage (the hazards), the SAM site with its
    rings, the target, the area; every kind once in the legend, in plain words."""
    from matplotlib.patches import Circle

    assert isinstance(layout_, Layout)
    lay = layout_
    r1, r2, r3, r4 = ranges_km
    w1, w2, w3, w4 = ring_labels(ranges_km)
    for k, radar in enumerate(lay.radars):
        coverage = f"radar coverage, a hazard ({radar.radius_km:g} km)" if k == 0 else None
        ax.add_patch(Circle(radar.position_km, radar.radius_km, color="red", alpha=0.25, lw=0, label=coverage))
        ax.plot(*radar.position_km, "r^", label="radar site" if k == 0 else None)
    ax.add_patch(Circle(lay.sam_km, r4, fill=False, color="tab:orange", ls="--", label=w4))
    ax.add_patch(Circle(lay.sam_km, r3, fill=False, color="tab:orange", ls="-", label=w3))
    ax.add_patch(Circle(lay.sam_km, r2, fill=False, color="tab:green", ls=":", label=w2))
    ax.add_patch(Circle(lay.sam_km, r1, fill=False, color="black", ls=":", label=w1))
    ax.plot(*lay.sam_km, "s", color="tab:orange", label="SAM site")
    ax.plot(*lay.target_km, "*", color="darkred", ms=12, label="target")
    ax.set_xlim(0, area_km)
    ax.set_ylim(0, area_km)
    ax.set_aspect("equal")
    ax.set_xlabel("east (km)")
    ax.set_ylabel("north (km)")


def draw_tracks(ax: Any, tracks_km: Mapping[str, Sequence[tuple[float, float]]]) -> None:
    """Each role's track so far and, as a dot, where it is now (the env's frame; the film animates the same)."""
    for role, track in tracks_km.items():
        if len(track):
            xs, ys = zip(*track)
            colour = ROLE_COLOURS.get(role)
            ax.plot(xs, ys, color=colour, lw=1.5, label=f"{role} UAV")
            ax.plot([xs[-1]], [ys[-1]], "o", color=colour)
