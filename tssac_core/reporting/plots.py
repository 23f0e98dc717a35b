"""Figures of one run and one mission: figure 7 (return and cost per epoch) and figure 8 (the multiplier) from a
run's metrics.csv, and figure 9 (a mission's trajectories, with its events labelled without overlap)."""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read_metrics(path: Path) -> list[dict[str, str]]:
    if not path.is_file():
        return []
    with path.open() as fh:
        return list(csv.DictReader(fh))


def _series(rows: list[dict[str, str]], role: str, key: str) -> tuple[list[int], list[float]]:
    sel = [r for r in rows if r["role"] == role and r[key] not in ("", "nan")]
    return [int(r["epoch"]) for r in sel], [float(r[key]) for r in sel]


def plot_training(metrics: Path, out: Path, cost_limit: float) -> None:
    """Write fig7_return_cost.png and fig8_multiplier.png next to the metrics."""
    rows = read_metrics(metrics)
    if not rows:
        return
    roles = [r for r in ("decoy", "detect", "strike") if any(row["role"] == r for row in rows)]
    fig, axes = plt.subplots(2, len(roles), figsize=(4.5 * len(roles), 6), squeeze=False)
    for col, role in enumerate(roles):
        x, y = _series(rows, role, "return")
        axes[0][col].plot(x, y, marker=".")
        axes[0][col].set_title(f"{role}: episode return")
        x, y = _series(rows, role, "cost")
        axes[1][col].plot(x, y, marker=".", color="tab:red")
        axes[1][col].axhline(cost_limit, color="red", ls="--", label=f"cost threshold C = {cost_limit:g}")
        axes[1][col].set_yscale("symlog", linthresh=10)  # early epochs cost hundreds, the limit is 3
        axes[1][col].set_title(f"{role}: episode cost")
        axes[1][col].set_xlabel("epoch")
        axes[1][col].legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(out / "fig7_return_cost.png", dpi=90)
    plt.close(fig)

    fig, axes = plt.subplots(1, len(roles), figsize=(4.5 * len(roles), 3.2), squeeze=False)
    for col, role in enumerate(roles):
        ax = axes[0][col]
        for key, label in (("beta", "beta"), ("beta_minus_xi", "beta - xi (effective)"), ("xi", "xi")):
            x, y = _series(rows, role, key)
            ax.plot(x, y, label=label)
        ax.set_title(f"{role}: cost multiplier (epoch means)")
        ax.set_xlabel("epoch")
        ax.legend()
    fig.tight_layout()
    fig.savefig(out / "fig8_multiplier.png", dpi=90)
    plt.close(fig)


# The map's drawing lives with the world (the env draws its own frames with it): the mission figures here, the film
# (tssac_core.reporting.mission_animation) and UavRoleEnv.render draw the same map.
from tssac_core.sim.drawing import LEGEND_BESIDE, ROLE_COLOURS, draw_layout, ring_labels  # noqa: E402

__all__ = ["LEGEND_BESIDE", "ROLE_COLOURS", "draw_layout", "plot_mission", "plot_training", "ring_labels"]


def plot_mission(
    path: Path,
    layout_: object,
    tracks_km: dict[str, list[tuple[float, float]]],
    ranges_km: tuple[float, float, float, float],
    events: Sequence[tuple[str, float, float]] = (),
    title: str = "",
    area_km: float = 100.0,
    backup_km: dict[str, list[list[tuple[float, float]]]] | None = None,
) -> None:
    """Figure 9: one mission's trajectories over the radars, the SAM's rings and the zones, with events.

    ``layout_`` is a :class:`tssac_core.sim.scenario.Layout`; ``tracks_km`` maps role name to (x, y) points;
    ``events`` are (label, x_km, y_km) markers (e.g. "radar on", "identified", "hit"); ``backup_km`` maps role name
    to the stretches flown under the runtime-assurance monitor's backup, drawn wide and dashed over the track.
    """
    fig, ax = plt.subplots(figsize=(9.8, 6.5))
    draw_layout(ax, layout_, ranges_km, area_km)
    for role, pts in tracks_km.items():
        if len(pts):
            xs, ys = zip(*pts)
            ax.plot(xs, ys, color=ROLE_COLOURS.get(role, None), lw=1.5, label=f"{role} UAV")
            ax.plot(xs[0], ys[0], "o", color=ROLE_COLOURS.get(role, None))
    labelled = False
    for stretches in (backup_km or {}).values():
        for pts in stretches:
            if len(pts) > 1:
                xs, ys = zip(*pts)
                ax.plot(
                    xs, ys, color="magenta", lw=4, ls="--", alpha=0.7, label=None if labelled else "backup (monitor)"
                )
                labelled = True
    for k, (_, x, y) in enumerate(events):
        ax.plot(x, y, "kx", label="mission event" if k == 0 else None)
    ax.set_title(title)
    ax.legend(**LEGEND_BESIDE)
    fig.tight_layout()
    place_labels(ax, events)  # after the layout: the labels are placed in the figure's final pixels
    fig.savefig(path, dpi=100)
    plt.close(fig)


LABEL_RADII_PT = (6.0, 14.0, 24.0, 36.0, 50.0, 66.0, 84.0, 104.0)
LABEL_ANGLES_DEG = (45.0, 135.0, -45.0, -135.0, 90.0, -90.0, 0.0, 180.0, 22.5, 157.5, -22.5, -157.5)


def place_labels(ax: Any, events: Sequence[tuple[str, float, float]]) -> list[Any]:
    """Annotate each (label, x, y) event so that no two labels overlap each other or leave the axes: each
    takes the first free spot on rings of growing radius around its point (a thin line joins a label set
    further out to its point). Events often fall together (radar on, identified and hit within a few km),
    where fixed offsets pile the words on top of each other. Returns the text artists."""
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    placed: list[Any] = []
    texts = []
    for label, x, y in events:
        text = None
        for radius in LABEL_RADII_PT:
            for angle in LABEL_ANGLES_DEG:
                dx, dy = radius * math.cos(math.radians(angle)), radius * math.sin(math.radians(angle))
                text = ax.annotate(
                    label,
                    (x, y),
                    xytext=(dx, dy),
                    textcoords="offset points",
                    fontsize=7.5,
                    ha="left" if dx > 1 else "right" if dx < -1 else "center",
                    va="bottom" if dy > 1 else "top" if dy < -1 else "center",
                    bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.85},
                    arrowprops={"arrowstyle": "-", "lw": 0.5, "color": "0.35"} if radius > LABEL_RADII_PT[0] else None,
                )
                box = text.get_window_extent(renderer)
                inside = frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
                if inside and not any(box.overlaps(other) for other in placed):
                    placed.append(box)
                    break
                text.remove()
                text = None
            if text is not None:
                break
        if text is None:  # nowhere free (dozens of events in one spot): the first ring, overlapping
            text = ax.annotate(label, (x, y), xytext=(4, 4), textcoords="offset points", fontsize=7.5)
        texts.append(text)
    return texts
