"""The typed configurations fly gives the processes it starts: one JSON round trip each, beside the dataclass
(tssac_core.sim.settings_json), and the world and companions fly starts configured as a user's equivalent command
lines would."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np
import pytest

from mavlink_bridge.companion import cli as companion_cli
from mavlink_bridge.companion import from_config
from mavlink_bridge.companion.config import CompanionConfig
from mavlink_bridge.estimation.filter_model import FilterModel
from mavlink_bridge.fly.child_configs import (
    LINGER_S,
    LOCKSTEP_SETPOINT_TIMEOUT_S,
    companion_config,
    tlog_path,
    world_config,
)
from mavlink_bridge.fly.config import DEFAULT_MODELS, FlyConfig, config_from_args
from mavlink_bridge.link.guided_commands import SetpointDialect
from sim_vehicles import __main__ as sitl_cli
from sim_vehicles import from_config as sitl_from_config
from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.deploy.numpy_actor import pilot_file
from tssac_core.sim.scenario import ROLES, DynamicsModel, Role, Scenario, ScenarioError, dump, load, sample_layout
from tssac_core.sim.settings_json import SettingsError, from_json, to_json
from tssac_core.sim.shield_tuning import ShieldTuning
from tssac_core.sim.sitl_config import ClockMode, LockstepStart, SitlConfig
from tssac_core.wire.mission_reset import MissionInput, NextMission

REPO = Path(__file__).resolve().parents[1]
RANDOM = REPO / "scenarios" / "random.yaml"
KEY = bytes(range(32))


def _fixed_scenario(seed: int = 4711) -> Scenario:
    """A random scenario's layout of ``seed``, fixed (as fly writes each mission's)."""
    scenario = load(RANDOM)
    return dataclasses.replace(scenario, layout=sample_layout(scenario, np.random.default_rng(seed)), random=None)


def _busy_config() -> CompanionConfig:
    """A configuration with every kind of field set away from its default."""
    return CompanionConfig(
        connection="udpout:127.0.0.1:14570",
        role=Role.DETECT,
        scenario=_fixed_scenario(),
        model=Path("models/tssac/detect.npz"),
        signing_key=KEY,
        tlog=Path("/tmp/mission-003/detect.tlog"),
        status_json=Path("/tmp/mission-003/detect.status.json"),
        lockstep=True,
        lockstep_grant_s=0.5,
        command_timeout_s=0.25,
        command_retries=12,
        duration_s=30.0,
        filter_model=FilterModel.CONSTANT_TURN_EKF,
        source_system=42,
        shield=ShieldConfig(margin_m=150.0, straight_leads_s=(0.0, 4.0)),
        lean_telemetry=True,
        setpoints=SetpointDialect.ARDUPLANE,
    )


def test_a_companion_config_survives_its_json_round_trip_equal() -> None:
    config = _busy_config()
    text = config.to_json()
    assert "\n" not in text  # one line: the first line of a companion's standard input
    assert CompanionConfig.from_json(text) == config
    plain = CompanionConfig(connection="udpout:127.0.0.1:14560", role=Role.DECOY, scenario=_fixed_scenario(7))
    assert CompanionConfig.from_json(plain.to_json()) == plain


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (lambda d: "{not json", "not JSON"),
        (lambda d: "[1, 2]", "expected a mapping"),
        (lambda d: json.dumps({**d, "lockstepp": True}), "lockstepp: unknown key"),
        (lambda d: json.dumps({k: v for k, v in d.items() if k != "role"}), "role: missing required field"),
        (lambda d: json.dumps({**d, "role": "pilot"}), "role: expected one of decoy, detect, strike"),
        (lambda d: json.dumps({**d, "signing_key": "xyz"}), "signing_key: expected bytes as hexadecimal digits"),
        (lambda d: json.dumps({**d, "lost_after_s": "10"}), "lost_after_s: expected a number"),
        (lambda d: json.dumps({**d, "command_timeout_s": -1.0}), "must be a positive number of seconds"),
        (lambda d: json.dumps({**d, "scenario": {**d["scenario"], "speed": 1}}), "scenario.speed: unknown key"),
    ],
)
def test_a_malformed_companion_config_is_one_clear_error(edit, needle: str) -> None:
    data = json.loads(_busy_config().to_json())
    with pytest.raises(SettingsError) as err:
        CompanionConfig.from_json(edit(data), "decoy.json")
    line = str(err.value)
    assert needle in line and line.startswith("decoy.json: ") and "\n" not in line, line


def test_a_companion_config_with_a_scenario_that_does_not_validate_is_refused() -> None:
    data = json.loads(_busy_config().to_json())
    data["scenario"]["dt_s"] = 5.0
    with pytest.raises(ScenarioError, match="scenario: dt_s: must be in"):
        CompanionConfig.from_json(json.dumps(data))


@dataclasses.dataclass(frozen=True)
class Inner:
    leads: tuple[float, ...] = (1.0, 2.5)


@dataclasses.dataclass(frozen=True)
class Outer:
    path: Path
    key: bytes | None
    role: Role
    inner: Inner | None = None
    count: int | None = None


def test_settings_json_keeps_paths_bytes_enums_and_nested_dataclasses() -> None:
    outer = Outer(Path("/a b/c.json"), b"\x00\xff", Role.STRIKE, Inner())
    assert json.loads(to_json(outer)) == {
        "path": "/a b/c.json",
        "key": "00ff",
        "role": "strike",
        "inner": {"leads": [1.0, 2.5]},
        "count": None,
    }
    assert from_json(Outer, to_json(outer), "outer") == outer


# ------------------------------------------------------------------------------ what fly gives a companion


def _fly_config(*extra: str) -> FlyConfig:
    return config_from_args(["--scenario", str(RANDOM), "--no-signing", *extra])


FLY_VARIANTS = [
    [],
    ["--pilot", "straight", "--shield"],
    ["--shield", "--shield-release-m", "300", "--shield-release-decisions", "1", "--shield-route-edge-km", "3"]
    + ["--shield-radar-view-km", "1"],
    ["--models", str(DEFAULT_MODELS), "--setpoints", "arduplane"],
    ["--speedup", "10"],
    ["--lockstep-grant-s", "0"],
    ["--full-telemetry"],
]


@pytest.mark.parametrize("extra", FLY_VARIANTS)
def test_fly_configures_a_companion_as_the_equivalent_command_line_would(tmp_path: Path, extra: list[str]) -> None:
    """The configuration fly builds for each companion is the one ``python -m mavlink_bridge.companion`` builds from
    the flags fly gave it before it handed configurations over (the behaviour is the same)."""
    cfg = dataclasses.replace(_fly_config(*extra), tlog_dir=tmp_path / "tlogs", signing_key_path=tmp_path / "k")
    scenario_file = tmp_path / "scenario.yaml"
    dump(_fixed_scenario(), scenario_file)
    (tmp_path / "k").write_bytes(KEY)
    for role in ROLES:
        status = tmp_path / f"{role.value}.status.json"
        tlog = tlog_path(cfg, 3, role)
        assert tlog == tmp_path / "tlogs" / "mission-003" / f"{role.value}.tlog"
        given = companion_config(cfg, role, "udpout:127.0.0.1:9", load(scenario_file), status, tlog, KEY)
        argv = ["--connect", "udpout:127.0.0.1:9", "--role", role.value, "--scenario", str(scenario_file)]
        argv += ["--status-json", str(status)]
        argv += ["--model", str(pilot_file(cfg.models, role))] if cfg.models is not None else ["--pilot", cfg.pilot]
        argv += ["--shield"] if cfg.shield else []
        tuning = cfg.shield_tuning
        argv += [
            "--shield-release-m",
            repr(tuning.release_m),
            "--shield-release-decisions",
            str(tuning.release_decisions),
        ]
        argv += ["--shield-route-edge-km", repr(tuning.route_edge_m / 1000.0)] if tuning.route_edge_m else []
        argv += ["--shield-radar-view-km", repr(tuning.radar_view_m / 1000.0)] if tuning.radar_view_m else []
        argv += ["--setpoints", cfg.setpoints.value]
        argv += ["--lockstep", "--lockstep-grant-s", repr(cfg.lockstep_grant_s)] if cfg.lockstep else []
        argv += ["--lean-telemetry"] if cfg.lean_telemetry else []
        argv += ["--tlog", str(tlog), "--signing-key", str(tmp_path / "k")]
        flags = companion_cli.config_from_args(companion_cli.build_parser().parse_args(argv))
        assert given == flags
        assert CompanionConfig.from_json(given.to_json()) == flags


def test_fly_hands_its_companions_the_monitors_tuning(tmp_path: Path) -> None:
    cfg = _fly_config("--shield", "--shield-release-m", "300", "--shield-release-decisions", "1")
    tuned = dataclasses.replace(cfg.shield_tuning, route_edge_m=2500.0, radar_view_m=1000.0)
    cfg = dataclasses.replace(cfg, shield_tuning=tuned)
    given = companion_config(cfg, ROLES[0], "udpout:127.0.0.1:9", _fixed_scenario(), tmp_path / "s.json", None, None)
    assert given.shield is not None
    assert (given.shield.release_margin_m, given.shield.release_decisions) == (300.0, 1)
    assert (given.shield.route_edge_margin_m, given.shield.radar_view_margin_m) == (2500.0, 1000.0)
    assert _fly_config("--shield").shield_tuning == ShieldTuning()  # untuned: the monitor's defaults


# ------------------------------------------------------------------------------ the companion's front end


def test_the_config_front_end_refuses_a_bad_config_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "decoy.json"
    bad.write_text(json.dumps({**json.loads(_busy_config().to_json()), "colour": "red"}))
    assert from_config.main(["--config-json", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"{from_config.PROG}: error: {bad}: colour: unknown key"), err
    assert from_config.main(["--config-json", str(tmp_path / "missing.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot read it (No such file or directory)" in err[0], err
    assert from_config.main([]) == 2
    assert "--config-json" in capsys.readouterr().err


def test_the_configuration_and_the_missions_share_standard_input(tmp_path: Path) -> None:
    """``--config-json -``: the configuration is the first line, the missions (--serve) the next ones."""
    config = _busy_config()
    mission = NextMission(1, tmp_path / "scenario.yaml", status_json=tmp_path / "detect.status.json")
    r, w = os.pipe()
    os.write(w, (config.to_json() + "\n" + mission.to_line()).encode())
    os.close(w)
    missions = MissionInput(r)
    try:
        assert from_config.read_config("-", missions) == config
        assert missions.next(lambda: False) == mission
        assert missions.next(lambda: False) is None  # the end of the input
    finally:
        os.close(r)


def test_an_empty_standard_input_is_one_clear_error() -> None:
    r, w = os.pipe()
    os.close(w)
    try:
        with pytest.raises(SettingsError, match="^--config-json -: standard input ended before the configuration$"):
            from_config.read_config("-", MissionInput(r))
    finally:
        os.close(r)


# ------------------------------------------------------------------------------ what fly gives the world


def _busy_world() -> SitlConfig:
    """A world configuration with every kind of field set away from its default."""
    return SitlConfig(
        scenario=_fixed_scenario(),
        seed=2**63 - 1,  # the largest seed --seed takes
        host="127.0.0.2",
        base_port=0,
        clock=ClockMode.LOCKSTEP,
        speedup=3.5,
        lockstep_start=LockstepStart.ANY,
        hold_start=True,
        signing_key=KEY,
        unsigned_monitors=True,
        truth_log=Path("/tmp/mission-001/truth.jsonl"),
        layout_out=Path("/tmp/layout.yaml"),
        tlog_dir=Path("/tmp/tlogs"),
        setpoint_timeout_s=5.0,
        linger_s=0.2,
        outputs=(("127.0.0.1", 14550), ("10.0.0.2", 14551)),
        dynamics_model=DynamicsModel.JSBSIM,
        aircraft="f16",
        serial_baud=57600,
        serial_byte_loss=0.01,
    )


def test_a_world_config_survives_its_json_round_trip_equal() -> None:
    for config in (_busy_world(), SitlConfig(scenario=load(RANDOM))):
        text = config.to_json()
        assert "\n" not in text
        assert SitlConfig.from_json(text) == config


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (lambda d: "", "not JSON"),
        (lambda d: json.dumps({**d, "sped": 2.0}), "sped: unknown key"),
        (lambda d: json.dumps({**d, "clock": "fast"}), "clock: expected one of realtime, lockstep"),
        (lambda d: json.dumps({**d, "outputs": [["127.0.0.1"]]}), "outputs[0]: expected a list of 2"),
        (lambda d: json.dumps({**d, "seed": 1.5}), "seed: expected an integer"),
        (lambda d: json.dumps({**d, "speedup": 0.0}), "speedup must be a positive number"),
        (lambda d: json.dumps({k: v for k, v in d.items() if k != "scenario"}), "scenario: missing required field"),
    ],
)
def test_a_malformed_world_config_is_one_clear_error(edit, needle: str) -> None:
    data = json.loads(_busy_world().to_json())
    with pytest.raises(SettingsError) as err:
        SitlConfig.from_json(edit(data), "sitl.json")
    line = str(err.value)
    assert needle in line and line.startswith("sitl.json: ") and "\n" not in line, line


@pytest.mark.parametrize("extra", [[], ["--speedup", "10"], ["--serial", "921600", "--serial-byte-loss", "0.001"]])
def test_fly_configures_the_world_as_the_equivalent_command_line_would(tmp_path: Path, extra: list[str]) -> None:
    """The world fly starts has the configuration ``python -m sim_vehicles`` builds from the flags fly gave it before
    it handed configurations over."""
    cfg = dataclasses.replace(_fly_config(*extra), signing_key_path=tmp_path / "k")
    (tmp_path / "k").write_bytes(KEY)
    scenario_file = tmp_path / "scenario.yaml"
    dump(_fixed_scenario(), scenario_file)
    truth = tmp_path / "truth.jsonl"
    given = world_config(cfg, load(scenario_file), 4712, truth, KEY)
    argv = ["--scenario", str(scenario_file), "--seed", "4712", "--base-port", "0", "--truth-log", str(truth)]
    argv += ["--linger-s", repr(LINGER_S)]
    if cfg.lockstep:
        argv += ["--lockstep", "--setpoint-timeout-s", str(LOCKSTEP_SETPOINT_TIMEOUT_S)]
    else:
        argv += ["--speedup", repr(cfg.speedup), "--hold-start"]
    argv += ["--signing-key", str(tmp_path / "k")]
    if cfg.serial_baud is not None:
        argv += ["--serial", str(cfg.serial_baud), "--serial-byte-loss", repr(cfg.serial_byte_loss)]
    flags = sitl_cli.config_from_args(sitl_cli.build_parser().parse_args(argv))
    assert given == flags
    assert SitlConfig.from_json(given.to_json()) == flags


def test_the_world_config_front_end_refuses_a_bad_config_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "sitl.json"
    bad.write_text(json.dumps({**json.loads(_busy_world().to_json()), "seed": -1.0}))
    assert sitl_from_config.main(["--config-json", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"{sitl_from_config.PROG}: error: {bad}: seed: expected an integer")
    r, w = os.pipe()
    os.close(w)
    try:
        with pytest.raises(ValueError, match="standard input ended before the configuration"):
            sitl_from_config.read_config("-", MissionInput(r))
    finally:
        os.close(r)
