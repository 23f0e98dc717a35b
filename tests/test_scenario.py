"""Scenario files: load/dump round trip, random layouts, and one clear error per kind of mistake."""

from __future__ import annotations

import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from tssac_core.sim.scenario import (
    Layout,
    Radar,
    ScenarioError,
    dump,
    from_dict,
    infeasibility,
    load,
    sample_layout,
    to_dict,
)


@pytest.mark.parametrize("name", ["strike.yaml", "random.yaml"])
def test_shipped_scenarios_round_trip(name, tmp_path):
    path = Path(__file__).resolve().parent.parent / "scenarios" / name
    s = load(path)
    dump(s, tmp_path / "copy.yaml")
    assert load(tmp_path / "copy.yaml") == s
    assert load(tmp_path / "copy.yaml").digest() == s.digest()


def test_digest_follows_the_task_not_the_expectations(random_path):
    import dataclasses

    from tssac_core.sim.scenario import Expect

    s = load(random_path)
    assert (
        dataclasses.replace(s, expect=Expect(episodes=3, min_success_rate=0.5, max_mean_cost=9.0)).digest()
        == s.digest()
    )
    assert dataclasses.replace(s, cost_limit=4.0).digest() != s.digest()


def test_random_layouts_are_feasible_and_seeded(random_path):
    s = load(random_path)
    a = [sample_layout(s, np.random.default_rng(3)) for _ in range(2)]
    assert a[0] == a[1]
    rng = np.random.default_rng(4)
    r4 = s.ranges.sam_detect_km
    for _ in range(40):
        lay = sample_layout(s, rng)
        assert infeasibility(s, lay, s.random.clearance_km) is None
        for radar in lay.radars:
            # zones stay clear of hazards
            assert math.dist(radar.position_km, lay.sam_km) >= r4 + radar.radius_km - 1e-9
            for start in lay.starts.values():
                assert math.dist(start.position_km, radar.position_km) > radar.radius_km + s.random.clearance_km


def test_every_drawn_layout_is_one_a_sitl_world_accepts(random_path, tmp_path):
    """One rule for both worlds: a random scenario whose radars may lie beyond the area's edge (all around the SAM,
    near the east edge) draws only layouts whose fixed-layout file a SITL world loads (fly writes each mission's
    layout so: a radar centre outside the area was flown by the batched world and refused by the SITL's)."""
    import dataclasses

    s = load(random_path)
    assert s.random is not None
    edge = dataclasses.replace(
        s, random=dataclasses.replace(s.random, sam_x_km=(70.0, 75.0), radar_bearing_spread_deg=180.0)
    )
    rng = np.random.default_rng(61)
    for k in range(60):
        lay = sample_layout(edge, rng)
        assert all(0 <= c <= s.area_km for radar in lay.radars for c in radar.position_km), k
        dump(dataclasses.replace(edge, layout=lay, random=None), tmp_path / "mission.yaml")
        assert load(tmp_path / "mission.yaml").layout == lay


def test_walled_in_start_is_infeasible(strike_path):
    s = load(strike_path)
    lay = s.layout
    # Ring the strike UAV's start with overlapping radars: no way out.
    cx, cy = lay.starts["strike"].position_km
    ring = tuple(
        Radar((cx + 9 * math.cos(a), cy + 9 * math.sin(a)), 5.0)
        for a in np.linspace(0, 2 * math.pi, 12, endpoint=False)
    )
    walled = Layout(lay.sam_km, lay.target_km, ring, lay.starts)
    assert infeasibility(s, lay, 0.0) is None
    problem = infeasibility(s, walled, 0.0)
    assert problem is not None and problem[0].startswith("layout.starts.")


def base(strike_path) -> dict:
    return yaml.safe_load(Path(strike_path).read_text())


def error_of(data, tmp_path) -> str:
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ScenarioError) as info:
        load(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(str(path))
    return message


def test_unknown_key(strike_path, tmp_path):
    data = base(strike_path)
    data["vehicles"]["decoy"]["speed_maximum"] = 3
    assert "vehicles.decoy.speed_maximum: unknown key" in error_of(data, tmp_path)


def test_wrong_type(strike_path, tmp_path):
    data = base(strike_path)
    data["episode_steps"] = "many"
    assert "episode_steps: expected an integer" in error_of(data, tmp_path)
    data = base(strike_path)
    data["layout"]["sam_km"] = [1.0]
    assert "layout.sam_km: expected a list of 2 numbers" in error_of(data, tmp_path)


def test_expectations(strike_path, tmp_path):
    data = base(strike_path)
    data["expect"] = {"episodes": 2, "min_success_rate": 0.9, "max_mean_cost": 3.0, "speedup": 10.0}
    path = tmp_path / "ok.yaml"
    path.write_text(yaml.safe_dump(data))
    assert load(path).expect.speedup == 10.0
    data["expect"]["speedup"] = 0.0
    assert "expect.speedup: must be positive" in error_of(data, tmp_path)
    data["expect"] = {"episodes": 0}
    assert "expect.episodes: must be positive" in error_of(data, tmp_path)
    data["expect"] = {"episodes": 6, "min_success_low95": 0.6, "max_cost_high95": 3.0}
    path.write_text(yaml.safe_dump(data))
    assert (load(path).expect.min_success_low95, load(path).expect.max_cost_high95) == (0.6, 3.0)
    data["expect"] = {"episodes": 6, "min_success_low95": 1.5}
    assert "expect.min_success_low95: must be in [0, 1]" in error_of(data, tmp_path)
    data["expect"] = {"episodes": 6, "max_cost_high95": -1.0}
    assert "expect.max_cost_high95: must be >= 0" in error_of(data, tmp_path)


def test_radius_out_of_range(strike_path, tmp_path):
    data = base(strike_path)
    data["layout"]["radars"][1]["radius_km"] = -4.0
    assert "layout.radars[1].radius_km: out of range" in error_of(data, tmp_path)
    data = base(strike_path)
    data["layout"]["radars"][0]["radius_km"] = 60.0
    assert "layout.radars[0].radius_km: out of range" in error_of(data, tmp_path)


def test_inconsistent_ranges(strike_path, tmp_path):
    data = base(strike_path)
    data["ranges"]["detect_km"] = 18.0
    assert "ranges: inconsistent: need R1" in error_of(data, tmp_path)


def test_start_inside_radar(strike_path, tmp_path):
    data = base(strike_path)
    data["layout"]["starts"]["detect"]["position_km"] = [38.0, 40.0]
    assert "layout.starts.detect: starts inside" in error_of(data, tmp_path)


def test_missing_and_exclusive_sections(strike_path, tmp_path):
    data = base(strike_path)
    del data["vehicles"]["strike"]
    assert "vehicles.strike: missing required vehicle" in error_of(data, tmp_path)
    data = base(strike_path)
    data["random"] = {}
    assert "give exactly one of 'layout' (fixed) or 'random'" in error_of(data, tmp_path)


def test_bad_probability_and_empty_range(random_path, tmp_path):
    data = yaml.safe_load(Path(random_path).read_text())
    data["link"]["packet_loss"] = 1.5
    assert "link.packet_loss: must be a probability" in error_of(data, tmp_path)
    data = yaml.safe_load(Path(random_path).read_text())
    data["random"]["sam_x_km"] = [70.0, 60.0]
    assert "random.sam_x_km: range is empty" in error_of(data, tmp_path)


def test_not_yaml_and_missing_file(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("name: [unclosed\n")
    with pytest.raises(ScenarioError, match="not valid YAML at line"):
        load(path)
    with pytest.raises(ScenarioError, match="cannot read file"):
        load(tmp_path / "absent.yaml")
    with pytest.raises(ScenarioError, match="expected a mapping"):
        from_dict(["a", "list"], "x.yaml")


def test_cli_reports_bad_scenario_in_one_line(strike_path, tmp_path):
    data = base(strike_path)
    data["ranges"]["sam_launch_km"] = "far"
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    proc = subprocess.run(
        [sys.executable, "-m", "tssac_core.evaluate", "--scenario", str(path), "--episodes", "1"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "ranges.sam_launch_km: expected a number" in lines[0]
    assert "Traceback" not in proc.stderr


def test_to_dict_is_plain_data(strike_path):
    data = to_dict(load(strike_path))
    yaml.safe_dump(data)  # raises on anything but plain data
    assert data["layout"]["radars"][0]["radius_km"] == 12.0


@pytest.mark.parametrize("encoding", ["utf-8-sig", "utf-16", "utf-16-le", "utf-16-be", "utf-32"])
def test_a_scenario_saved_in_any_yaml_encoding_loads_the_same(strike_path, tmp_path, encoding):
    text = Path(strike_path).read_text()
    # utf-16 / utf-32 write their byte order mark; the -le / -be codecs do not, so give them one.
    path = tmp_path / f"{encoding}.yaml"
    path.write_bytes(("\ufeff" if encoding.endswith(("-le", "-be")) else "").encode(encoding) + text.encode(encoding))
    assert load(path) == load(strike_path)


def test_a_file_in_another_encoding_or_too_large_is_one_error_at_once(strike_path, tmp_path):
    latin = tmp_path / "latin1.yaml"
    latin.write_bytes(b"# caf\xe9\n" + Path(strike_path).read_bytes())
    with pytest.raises(ScenarioError, match=r"latin1.yaml: not UTF-8 text \(byte 5\); save it as UTF-8"):
        load(latin)
    huge = tmp_path / "huge.yaml"
    with huge.open("wb") as fh:  # 50 MB of one YAML scalar: PyYAML alone took more than 90 s over it
        fh.write(b"a" * (50 << 20))
    t0 = time.monotonic()
    with pytest.raises(ScenarioError, match="file larger than 1024 KiB"):
        load(huge)
    assert time.monotonic() - t0 < 2.0


def _hostile_files(strike_path: Path, tmp_path: Path) -> list[Path]:
    latin = tmp_path / "latin1.yaml"
    latin.write_bytes(b"# caf\xe9\n" + strike_path.read_bytes())
    huge = tmp_path / "huge.yaml"
    huge.write_bytes(b"a" * (2 << 20))
    return [latin, huge]


def test_every_command_reports_a_hostile_scenario_file_in_one_line_and_exits_2(strike_path, tmp_path, capsys):
    from mavlink_bridge.fly.cli import main as fly
    from tssac_core.common.cli import run
    from tssac_core.evaluate import main as evaluate
    from tssac_core.train.cli import main as train

    for path in _hostile_files(Path(strike_path), tmp_path):
        commands = {
            "evaluate": lambda: run(evaluate, ["--scenario", str(path), "--episodes", "1"]),
            "fly": lambda: fly(["--scenario", str(path), "--pilot", "guidance", "--no-progress"]),
            "train": lambda: run(
                train, ["--algo", "sac", "--seed", "0", "--out", str(tmp_path / "run"), "--scenario", str(path)]
            ),
        }
        for name, command in commands.items():
            capsys.readouterr()
            assert command() == 2, name
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and path.name in err[0] and "Traceback" not in err[0], (name, err)
        assert not (tmp_path / "run").exists()
