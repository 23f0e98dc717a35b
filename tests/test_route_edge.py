"""Giving the team its way back (:mod:`tssac_core.sim.shield_tuning`): a route that leaves the monitor's backups
their room at the geofence (``--shield-route-edge-km``: the policies' route observation treats a band inside the area's
edge as a hazard, in the batched world and in the companion alike) and a quicker hand-back (``--shield-release-m``,
``--shield-release-decisions``), each safe; the options need the monitor and sane values."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mavlink_bridge.companion.cli import main as companion_main
from mavlink_bridge.companion.config import CompanionConfig
from mavlink_bridge.companion.held_pilot import make_pilot
from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.common.cli import run
from tssac_core.deploy.policy import load_team
from tssac_core.evaluate import main as evaluate_main
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.pilots import PolicyPilot
from tssac_core.sim.routes import RouteConfig
from tssac_core.sim.scenario import Role, load

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = ROOT / "models" / "tssac"
STRIKE, MODEL = str(ROOT / "scenarios" / "strike.yaml"), str(SHIPPED / "strike.npz")


def closest_to_the_edge_m(trajectories: np.ndarray) -> np.ndarray:
    """Per mission, the closest any UAV came to the area's edge (m), from recorded (M, T, 3, 2) positions."""
    x, y = trajectories[..., 0], trajectories[..., 1]
    return np.nanmin(np.minimum(np.minimum(x, y), np.minimum(100_000.0 - x, 100_000.0 - y)), axis=(1, 2))


def test_the_shipped_team_shown_the_band_keeps_out_of_it_where_its_trained_route_ran_along_the_edge() -> None:
    # Missions 236 and 301 of seed 9100001 (found on that seed): the trained route takes a UAV round the radars within
    # 0.7 and 2.4 km of the edge; shown the 3 km band, the team goes round the other way, more than 3 km inside.
    scenario = load(ROOT / "scenarios" / "random.yaml")
    team = load_team(SHIPPED)
    flown = {
        edge: fly_missions(
            scenario, team, 0, 9100001, indices=[236, 301], shield=ShieldConfig(route_edge_margin_m=edge), record=True
        )
        for edge in (0.0, 3000.0)
    }
    trained, banded = (closest_to_the_edge_m(flown[e].trajectories) for e in (0.0, 3000.0))  # type: ignore[arg-type]
    assert (trained < 3000.0).all()  # the negative control: as trained, both routes run in the band
    assert (banded > 3000.0).all()
    for results in flown.values():
        assert results.cost.sum() == 0 and not results.out_of_area.any()  # the monitor keeps both safe


def test_the_companion_shows_its_policy_the_route_its_monitor_asks_for() -> None:
    scenario = load(ROOT / "scenarios" / "strike.yaml")
    model = SHIPPED / "strike.npz"
    for shield, edge in ((None, 0.0), (ShieldConfig(), 0.0), (ShieldConfig(route_edge_margin_m=2500.0), 2500.0)):
        config = CompanionConfig("udpout:127.0.0.1:9", Role.STRIKE, scenario, model=model, shield=shield)
        again = CompanionConfig.from_json(config.to_json())  # how fly hands a companion its configuration
        assert again.shield == shield
        pilot = make_pilot(again).pilot
        assert isinstance(pilot, PolicyPilot)
        assert pilot.routes.cfg == RouteConfig(edge_margin_m=edge)


NEEDS_SHIELD = (
    "--shield-release-m, --shield-release-decisions and --shield-route-edge-km tune the monitor: they need --shield"
)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--shield-route-edge-km", "3"], NEEDS_SHIELD),
        (["--shield-release-m", "300"], NEEDS_SHIELD),
        (["--shield", "--shield-route-edge-km", "-1"], "--shield-route-edge-km must be a finite number >= 0, got -1"),
        (["--shield", "--shield-route-edge-km", "nan"], "--shield-route-edge-km must be a finite number >= 0, got nan"),
        (["--shield", "--shield-release-m", "inf"], "--shield-release-m must be a finite number >= 0, got inf"),
        (["--shield", "--shield-release-decisions", "0"], "--shield-release-decisions must be >= 1, got 0"),
    ],
)
def test_a_bad_tuning_is_one_line_before_anything_flies(capsys, argv: list[str], message: str) -> None:
    for main, base in (
        (evaluate_main, ["--models", str(SHIPPED), "--episodes", "1"]),
        (
            companion_main,
            ["--connect", "udpout:127.0.0.1:9", "--role", "strike", "--scenario", STRIKE, "--model", MODEL],
        ),
    ):
        assert run(main, base + argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and message in err
