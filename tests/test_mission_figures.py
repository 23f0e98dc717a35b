"""fly's figures (issue 42): the plot's legend in plain words, the film (``--animate``), and the bad file names."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402
from PIL import Image  # noqa: E402

from mavlink_bridge.fly.config import config_from_args  # noqa: E402
from tssac_core.common.cli import UsageError  # noqa: E402
from tssac_core.reporting.mission_animation import (  # noqa: E402
    AnimationFormatError,
    MissionFilm,
    check_target,
    frame_steps,
    write_film,
)
from tssac_core.reporting.plots import plot_mission, ring_labels  # noqa: E402
from tssac_core.sim.scenario import load  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RANGES = (10.0, 13.0, 17.0, 20.0)


def layout():
    return load(ROOT / "scenarios" / "strike.yaml").layout


def straight_tracks(steps: int) -> dict[str, list[tuple[float, float]]]:
    return {role: [(10.0 + 0.1 * k, 10.0 + 0.1 * k + j) for k in range(steps)] for j, role in enumerate(["decoy"])}


def test_the_plot_legend_names_every_kind_in_plain_words(tmp_path, monkeypatch):
    import matplotlib.axes

    seen: list[list[str]] = []
    real = matplotlib.axes.Axes.legend

    def legend(ax, *args, **kwargs):
        made = real(ax, *args, **kwargs)
        seen.append([t.get_text() for t in made.get_texts()])
        return made

    monkeypatch.setattr(matplotlib.axes.Axes, "legend", legend)
    plot_mission(tmp_path / "m.png", layout(), straight_tracks(50), RANGES, [("hit", 11.0, 11.0)])
    words = seen[0]
    assert words[:2] == ["radar coverage, a hazard (12 km)", "radar site"]
    assert set(ring_labels(RANGES)) <= set(words) and {"SAM site", "target", "decoy UAV", "mission event"} <= set(words)
    assert not any(w.startswith(("R1", "R2", "R3", "R4")) or " R" in w for w in words)


def test_the_film_shows_what_happened_by_then(tmp_path, capsys):
    steps = 48  # one frame per step (a longer mission is drawn at a stride: test_frame_steps_keep_the_last_step)
    film = MissionFilm(
        layout=layout(),
        tracks_km=straight_tracks(steps),
        ranges_km=RANGES,
        dt_s=0.1,
        events=[(24, "radar on", 16.0, 16.0)],
        backup_steps={"decoy": [(8, 16)]},
        title="test",
    )
    out = write_film(film, tmp_path / "m.gif", progress=True)
    said = capsys.readouterr().err
    assert "drawing m.gif" in said and f"/{len(frame_steps(steps))}" in said  # a bar of the frames while it draws
    with Image.open(out) as gif:
        # Pillow folds identical frames together: at most one frame per drawn step.
        assert 10 < gif.n_frames <= len(frame_steps(steps)) and gif.size[0] > gif.size[1]
        gif.seek(0)
        first = gif.convert("RGB").tobytes()
        gif.seek(gif.n_frames - 1)
        last = gif.convert("RGB").tobytes()
    assert first != last  # the track grows, the event and the backup stretch appear


def test_frame_steps_keep_the_last_step():
    assert frame_steps(10, 4) == [0, 3, 6, 9]
    assert frame_steps(4001)[-1] == 4000 and len(frame_steps(4001)) <= 241


def test_bad_film_names_are_one_line(tmp_path, monkeypatch):
    with pytest.raises(AnimationFormatError, match="a .gif or an .mp4"):
        check_target(tmp_path / "m.avi")
    monkeypatch.setattr("shutil.which", lambda name: None)
    with pytest.raises(UsageError, match="needs ffmpeg on PATH"):
        config_from_args(["--scenario", str(ROOT / "scenarios" / "strike.yaml"), "--animate", str(tmp_path / "m.mp4")])
    monkeypatch.setattr("shutil.which", lambda name: "/usr/bin/ffmpeg")
    cfg = config_from_args(
        ["--scenario", str(ROOT / "scenarios" / "strike.yaml"), "--animate", str(tmp_path / "m.mp4")]
    )
    assert cfg.animate_path == (tmp_path / "m.mp4").resolve()
