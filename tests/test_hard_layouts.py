"""Hard training layouts: the start detour, the share of hard draws, and runs without them unchanged to the bit."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from tssac_core.sim.env import RoleTask
from tssac_core.sim.hard_layouts import HardLayouts, LayoutSource, start_detours_km
from tssac_core.sim.routes import RouteMap
from tssac_core.sim.scenario import Layout, Radar, Role, Start, load, sample_layout
from tssac_core.sim.world_state import snapshot

RANDOM = load("scenarios/random.yaml")


def layout_with_radar(radar_km: tuple[float, float]) -> Layout:
    """The SAM at (70, 50), every UAV at (10, 50), one radar of 12 km radius."""
    return Layout(
        sam_km=(70.0, 50.0),
        target_km=(70.0, 51.0),
        radars=(Radar(position_km=radar_km, radius_km=12.0),),
        starts={r.value: Start(position_km=(10.0, 50.0), heading_deg=0.0) for r in Role},
    )


def test_start_detour_is_the_way_round_a_radar_on_the_line():
    clear, blocked = start_detours_km(RANDOM, [layout_with_radar((30.0, 85.0)), layout_with_radar((30.0, 50.0))])
    assert clear.shape == (3,) and blocked.shape == (3,)
    assert clear.max() < 0.03 * 40.0  # a free line: no detour but the grid metric's (<= 2.7% of 40 km)
    # A 12 km radar (kept 3 km clear) halfway on the 40 km line: tangent, arc, tangent is 47.3 km at least.
    assert blocked.min() > 7.0
    np.testing.assert_allclose(blocked, blocked[0])  # the three UAVs start at the same point


def test_without_hard_layouts_the_draws_are_the_scenarios_own():
    a, b = np.random.default_rng(7), np.random.default_rng(7)
    source = LayoutSource(RANDOM, HardLayouts(fraction=0.0))
    assert [source.draw(a) for _ in range(20)] == [sample_layout(RANDOM, b) for _ in range(20)]
    assert a.random() == b.random()  # and the generator is left where sample_layout leaves it


def test_every_draw_is_hard_at_fraction_one():
    source = LayoutSource(RANDOM, HardLayouts(fraction=1.0, detour_km=20.0))
    rng = np.random.default_rng(11)
    layouts = [source.draw(rng) for _ in range(15)]
    assert start_detours_km(RANDOM, layouts).max(axis=1).min() >= 20.0


def test_the_share_of_hard_layouts_follows_the_fraction():
    rng = np.random.default_rng(3)
    natural = start_detours_km(RANDOM, [sample_layout(RANDOM, rng) for _ in range(100)]).max(axis=1) >= 20.0
    mixed_source = LayoutSource(RANDOM, HardLayouts(fraction=0.5, detour_km=20.0))
    mixed = start_detours_km(RANDOM, [mixed_source.draw(rng) for _ in range(100)]).max(axis=1) >= 20.0
    # Half forced hard, half the natural draw: 0.5 + 0.5 p against p (p ~ 0.25 on random.yaml).
    assert 0.1 < natural.mean() < 0.4
    expected = 0.5 + 0.5 * natural.mean()
    assert abs(mixed.mean() - expected) < 0.12


def test_a_threshold_no_layout_reaches_gives_the_hardest_drawn():
    source = LayoutSource(RANDOM, HardLayouts(fraction=1.0, detour_km=1000.0, max_draws=5))
    rng = np.random.default_rng(5)
    replay = copy.deepcopy(rng)
    chosen = source.draw(rng)
    replay.random()  # the draw that decided "hard"
    candidates = [sample_layout(RANDOM, replay) for _ in range(5)]
    detours = start_detours_km(RANDOM, candidates).max(axis=1)
    assert chosen == candidates[int(np.argmax(detours))]


def test_training_worlds_start_on_hard_layouts():
    task = RoleTask(RANDOM, Role.DETECT, n=4, seed=1, hard_layouts=HardLayouts(fraction=1.0, detour_km=20.0))
    task.reset()
    assert (RouteMap().detour_m(snapshot(task.world)).max(axis=1) >= 20_000.0).all()


@pytest.mark.parametrize(
    "fraction, detour_km, max_draws", [(-0.1, 20.0, 10), (1.5, 20.0, 10), (0.5, -1.0, 10), (0.5, 20.0, 0)]
)
def test_bad_settings_are_refused(fraction, detour_km, max_draws):
    with pytest.raises(ValueError):
        HardLayouts(fraction, detour_km, max_draws)


def test_bad_arguments_are_one_line(tmp_path, capsys):
    from tssac_core.common.cli import run
    from tssac_core.train.cli import main

    assert run(main, ["--out", str(tmp_path / "x"), "--hard-layouts", "1.5"]) == 2
    err = capsys.readouterr().err
    assert "--hard-layouts: expected a fraction in [0, 1], got 1.5" in err and "Traceback" not in err
