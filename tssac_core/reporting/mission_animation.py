"""``fly --animate FILE.gif|mp4``: one mission as a film, for people who would rather watch than read.

The map of :func:`tssac_core.reporting.plots.draw_layout` (radar coverage, the SAM's rings, the target; the legend in
plain words), then frame by frame: each UAV's track so far and its position, the stretches flown under the
runtime-assurance monitor's backup as they are flown, the mission events (radar on, identified, hit, hazard,
left area) from the moment they happen, and the mission clock.

What does not move (the map, the axes, the legend: most of the figure's drawing) is drawn once; each frame draws only
what moves over a copy of it (matplotlib's blitting), and is taken from the canvas's pixels. matplotlib's own
writers redraw the whole figure for every frame (the strike mission's 240 frames took 55 s, 75 s of CPU; now 5 s of
CPU). A GIF is written with Pillow, every frame in one palette (the last frame's
colours: it shows everything that any frame shows), which also saves quantizing each frame on its own; an MP4 is
piped to ffmpeg from PATH, which the command checks before flying. A progress bar on stderr counts the frames.
"""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from PIL import Image

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


def write_film(film: MissionFilm, path: Path, progress: bool = False) -> Path:
    """Draw ``film`` into ``path`` (.gif with Pillow, .mp4 with ffmpeg); returns the path. ``progress``: a bar of the
    frames drawn on stderr."""
    check_target(path)
    from tqdm import tqdm

    steps = frame_steps(max((len(t) for t in film.tracks_km.values()), default=0))
    path.parent.mkdir(parents=True, exist_ok=True)
    with tqdm(
        total=len(steps), desc=f"drawing {path.name}", unit="frame", disable=not progress, file=sys.stderr, leave=False
    ) as bar:
        frames = _frames(film, steps, bar.update)
        if path.suffix.lower() == ".gif":
            _write_gif(frames, path)
        else:
            _write_mp4(frames, path)
    return path


def _frames(film: MissionFilm, steps: list[int], done: Any) -> Iterator[Image.Image]:
    """The film's frames as RGB images, the last step's first (its colours are the GIF's palette), then every step of
    ``steps`` in order; ``done(1)`` after each frame of ``steps``."""
    import matplotlib.pyplot as plt  # matplotlib here: the command checks the file name without it
    from PIL import Image

    from tssac_core.reporting.plots import (  # Agg backend (tssac_core.reporting.plots)
        LEGEND_BESIDE,
        ROLE_COLOURS,
        draw_layout,
    )

    tracks = {role: np.asarray(track, dtype=float).reshape(-1, 2) for role, track in film.tracks_km.items()}
    fig, ax = plt.subplots(figsize=(9.8, 6.5))
    try:
        draw_layout(ax, film.layout, film.ranges_km, film.area_km)
        lines, heads, backups = {}, {}, {}
        for role in tracks:
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
        tracked = [artist for role in tracks for artist in (lines[role], heads[role], backups[role])]
        moving: list[Artist] = [
            *tracked,
            event_marks,
            clock,
            *texts,
        ]  # in the order they were made, as the figure draws
        for artist in moving:
            artist.set_animated(True)  # left out of the background
        canvas = fig.canvas
        canvas.draw()
        background = canvas.copy_from_bbox(fig.bbox)  # type: ignore[attr-defined]

        def draw(step: int) -> Image.Image:
            canvas.restore_region(background)  # type: ignore[attr-defined]
            for role, track in tracks.items():
                upto = track[: step + 1]
                if len(upto):
                    lines[role].set_data(upto[:, 0], upto[:, 1])
                    heads[role].set_data(upto[-1:, 0], upto[-1:, 1])
                flown = [
                    np.vstack([track[a : min(b, step + 1)], [[math.nan, math.nan]]])
                    for a, b in film.backup_steps.get(role, [])
                    if a <= step
                ]
                joined = np.vstack(flown) if flown else np.empty((0, 2))
                backups[role].set_data(joined[:, 0], joined[:, 1])
            seen = [(x, y) for k, _, x, y in film.events if k <= step]
            event_marks.set_data([p[0] for p in seen], [p[1] for p in seen])
            for text, (k, *_rest) in zip(texts, film.events):
                text.set_visible(k <= step)
            clock.set_text(f"t = {step * film.dt_s:.0f} s")
            for artist in moving:
                fig.draw_artist(artist)
            pixels = canvas.buffer_rgba()  # type: ignore[attr-defined]
            return Image.frombuffer("RGBA", canvas.get_width_height(), pixels, "raw", "RGBA", 0, 1).convert("RGB")

        yield draw(steps[-1])
        for step in steps:
            yield draw(step)
            done(1)
    finally:
        plt.close(fig)


def _write_gif(frames: Iterator[Image.Image], path: Path) -> None:
    """Every frame in the first frame's palette (adaptive, 255 colours), without dithering; Pillow stores only the
    part of each frame that changed."""
    from PIL import Image

    palette = next(frames).quantize(colors=255, method=Image.Quantize.FASTOCTREE)
    images = [f.quantize(palette=palette, dither=Image.Dither.NONE) for f in frames]
    images[0].save(path, save_all=True, append_images=images[1:], duration=round(1000 / FPS), loop=0)


def _write_mp4(frames: Iterator[Image.Image], path: Path) -> None:
    """H.264 from ffmpeg on PATH, fed raw RGB frames on its stdin (the first of ``frames`` is only the palette's)."""
    next(frames)
    first = next(frames)
    width, height = first.size
    command = [
        "ffmpeg", "-hide_banner", "-loglevel", "error", "-y",
        "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{width}x{height}", "-r", str(FPS), "-i", "-",
        "-vf", "scale=trunc(iw/2)*2:trunc(ih/2)*2", "-pix_fmt", "yuv420p", str(path),
    ]  # fmt: skip
    with subprocess.Popen(command, stdin=subprocess.PIPE, stderr=subprocess.PIPE) as ffmpeg:
        assert ffmpeg.stdin is not None
        try:
            for frame in (first, *frames):
                ffmpeg.stdin.write(frame.tobytes())
        except BrokenPipeError:
            pass  # ffmpeg stopped: its message follows
        finally:
            ffmpeg.stdin.close()
        said = ffmpeg.stderr.read().decode(errors="replace").strip() if ffmpeg.stderr else ""
    if ffmpeg.returncode != 0:
        raise AnimationFormatError(f"{path}: ffmpeg failed: {said.splitlines()[-1] if said else ffmpeg.returncode}")
