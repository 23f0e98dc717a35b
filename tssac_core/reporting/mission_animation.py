"""``fly --animate FILE.gif|mp4``: one mission as a film, for people who would rather watch than read.

The map of :func:`tssac_core.reporting.plots.draw_layout` (radar coverage, the SAM's rings, the target; the legend in
plain words), then frame by frame: each UAV's track so far and its position, the stretches flown under the
runtime-assurance monitor's backup as they are flown, the mission events (radar on, identified, hit, hazard,
left area) from the moment they happen, and the mission clock. A GIF is written with Pillow (matplotlib's
``PillowWriter``); an MP4 needs ffmpeg on PATH (``FFMpegWriter``), which the command checks before flying.
"""

from __future__ import annotations

import math
import shutil
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.artist import Artist

MAX_FRAMES = 240
"""Frames per film at most (a 4,000-step mission is drawn every 17th step): small files, a few seconds to write."""
FPS = 20
FORMATS = (".gif", ".mp4")


class AnimationFormatError(ValueError):
    """A file name the animation cannot be written to; ``str()`` is one line (a bad --animate is bad input)."""


def check_target(path: Path) -> None:
    """AnimationFormatError unless ``path`` ends in .gif, or in .mp4 with ffmpeg on PATH."""
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise AnimationFormatError(f"{path}: --animate writes a .gif or an .mp4, not {suffix or 'a file without one'}")
    if suffix == ".mp4" and shutil.which("ffmpeg") is None:  # matplotlib's FFMpegWriter runs "ffmpeg" from PATH
        raise AnimationFormatError(f"{path}: an .mp4 needs ffmpeg on PATH (not found); write a .gif instead")


@dataclass
class MissionFilm:
    """What the film shows, in world steps of ``dt_s`` seconds."""

    layout: object
    """A :class:`tssac_core.sim.scenario.Layout`."""
    tracks_km: dict[str, list[tuple[float, float]]]
    """Role -> its position at every world step."""
    ranges_km: tuple[float, float, float, float]
    dt_s: float
    area_km: float = 100.0
    events: Sequence[tuple[int, str, float, float]] = ()
    """(step, label, x_km, y_km)."""
    backup_steps: dict[str, list[tuple[int, int]]] = field(default_factory=dict)
    """Role -> the [first, last) steps flown under the backup."""
    title: str = ""


def frame_steps(steps: int, max_frames: int = MAX_FRAMES) -> list[int]:
    """The world steps drawn: evenly spaced, the last step always included."""
    if steps <= 0:
        return [0]
    stride = max(1, math.ceil(steps / max_frames))
    out = list(range(0, steps, stride))
    if out[-1] != steps - 1:
        out.append(steps - 1)
    return out


def write_film(film: MissionFilm, path: Path) -> Path:
    """Draw ``film`` into ``path`` (.gif with Pillow, .mp4 with ffmpeg); returns the path."""
    check_target(path)
    import matplotlib.pyplot as plt  # matplotlib here: the command checks the file name without it
    from matplotlib import animation

    from tssac_core.reporting.plots import (  # Agg backend (tssac_core.reporting.plots)
        LEGEND_BESIDE,
        ROLE_COLOURS,
        draw_layout,
    )

    steps = max((len(t) for t in film.tracks_km.values()), default=0)
    fig, ax = plt.subplots(figsize=(9.8, 6.5))
    draw_layout(ax, film.layout, film.ranges_km, film.area_km)
    lines, heads, backups = {}, {}, {}
    for role in film.tracks_km:
        colour = ROLE_COLOURS.get(role)
        (lines[role],) = ax.plot([], [], color=colour, lw=1.5, label=f"{role} UAV")
        (heads[role],) = ax.plot([], [], "o", color=colour)
        (backups[role],) = ax.plot([], [], color="magenta", lw=4, ls="--", alpha=0.7)
    if any(film.backup_steps.values()):
        backups[next(iter(backups))].set_label("backup (monitor) flying")
    (event_marks,) = ax.plot([], [], "kx", label="mission event")
    clock = ax.text(0.02, 0.97, "", transform=ax.transAxes, va="top", fontsize=9)
    texts = [
        ax.annotate(label, (x, y), xytext=(5, 5), textcoords="offset points", fontsize=7.5, visible=False)
        for _, label, x, y in film.events
    ]
    ax.set_title(film.title)
    ax.legend(**LEGEND_BESIDE)
    fig.tight_layout()

    def draw(step: int) -> list[Artist]:
        for role, track in film.tracks_km.items():
            upto = track[: step + 1]
            if upto:
                xs, ys = zip(*upto)
                lines[role].set_data(xs, ys)
                heads[role].set_data([xs[-1]], [ys[-1]])
            flown = [
                p for a, b in film.backup_steps.get(role, []) for p in track[a : min(b, step + 1)] + [(math.nan,) * 2]
            ]
            backups[role].set_data([p[0] for p in flown], [p[1] for p in flown])
        seen = [(x, y) for k, _, x, y in film.events if k <= step]
        event_marks.set_data([p[0] for p in seen], [p[1] for p in seen])
        for text, (k, *_rest) in zip(texts, film.events):
            text.set_visible(k <= step)
        clock.set_text(f"t = {step * film.dt_s:.0f} s")
        return [*lines.values(), *heads.values(), *backups.values(), event_marks, clock, *texts]

    writer = animation.PillowWriter(fps=FPS) if path.suffix.lower() == ".gif" else animation.FFMpegWriter(fps=FPS)
    path.parent.mkdir(parents=True, exist_ok=True)
    with writer.saving(fig, str(path), dpi=fig.dpi):  # one figure draw per frame (FuncAnimation draws two or three)
        for step in frame_steps(steps):
            draw(step)
            writer.grab_frame()
    plt.close(fig)
    return path
