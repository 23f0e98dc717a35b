"""Actors as ONNX files (``export --format onnx``): the same actions as the numpy actors, the manifest round trip, the
same figures in ``evaluate``, a mission in ``fly``, and one clear line for every file that does not fit."""

from __future__ import annotations

import json
import pickle
import re
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper

from mavlink_bridge.companion.cli import main as companion_main
from mavlink_bridge.fly.cli import main as fly_main
from tssac_core.common.cli import run
from tssac_core.common.errors import CheckpointError
from tssac_core.deploy.export import main as export_main
from tssac_core.deploy.manifest import MANIFEST, check_command, read_manifest, record
from tssac_core.deploy.numpy_actor import NumpyPolicy, load_actor, load_policy, pilot_file
from tssac_core.deploy.onnx_actor import REQUIRED, OnnxPolicy
from tssac_core.evaluate import main as evaluate_main
from tssac_core.sim.observation import ObservationMode, observation_bounds
from tssac_core.sim.scenario import ROLES, Role

REPO = Path(__file__).resolve().parent.parent
SHIPPED = REPO / "models" / "tssac"
STRIKE = REPO / "scenarios" / "strike.yaml"


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The shipped team exported by the command: ``export models/tssac --format onnx --out DIR2`` (read only)."""
    out = tmp_path_factory.mktemp("onnx") / "team"
    assert export_main([str(SHIPPED), "--format", "onnx", "--out", str(out)]) == 0
    return out


@pytest.fixture()
def team(exported: Path, tmp_path: Path) -> Path:
    """A copy of the exported team that a test may damage."""
    return Path(shutil.copytree(exported, tmp_path / "team"))


def one_error_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    return lines[0]


def observations(n: int, seed: int) -> np.ndarray:
    """``n`` route observations drawn uniformly within the observation's bounds, float32 (n, 24)."""
    low, high = observation_bounds(ObservationMode.ROUTE)
    return np.random.default_rng(seed).uniform(low, high, (n, low.size)).astype(np.float32)


# ------------------------------------------------------------------------------ the same actor


@pytest.mark.parametrize("role", ROLES, ids=lambda r: r.value)
def test_onnx_and_numpy_actors_give_the_same_actions(exported: Path, role: Role):
    numpy_actor = NumpyPolicy.load(SHIPPED / f"{role.value}.npz", role)
    onnx_actor = OnnxPolicy.load(exported / f"{role.value}.onnx", role)
    face = ("role", "obs_dim", "act_dim", "observation_mode", "action_repeat")
    assert [getattr(onnx_actor, k) for k in face] == [getattr(numpy_actor, k) for k in face]
    obs = observations(10_000, seed=62 + ROLES.index(role))
    batch = onnx_actor.predict(obs)
    assert batch.shape == (10_000, 2) and batch.dtype == np.float64
    # Both float32, their sums over 128-wide layers in other orders: measured at most 6e-6 apart.
    np.testing.assert_allclose(batch, numpy_actor.predict(obs), rtol=0, atol=1e-5)
    singles = np.array([onnx_actor(o) for o in obs[:500]])  # the companion's call: one observation (24,) -> (2,)
    np.testing.assert_allclose(singles, numpy_actor.act(obs[:500]), rtol=0, atol=1e-5)
    assert np.abs(batch).max() > 0.5, "the actions should not all be near zero (is tanh applied to the mean half?)"
    with pytest.raises(ValueError, match="takes 24"):
        onnx_actor.act(obs[:, :-1])


def test_a_graph_for_one_observation_at_a_time_flies_a_batch_row_by_row(team: Path):
    """An exporter without a dynamic batch axis writes input (1, 24): the companion's call as it is, a batch (the
    batched evaluation's) row by row."""

    def batch_of_one(model: onnx.ModelProto) -> None:
        for value in (model.graph.input[0], model.graph.output[0]):
            value.type.tensor_type.shape.dim[0].dim_value = 1

    rewrite(team / "decoy.onnx", batch_of_one)
    actor = OnnxPolicy.load(team / "decoy.onnx", Role.DECOY)
    obs = observations(20, seed=2)
    expected = NumpyPolicy.load(SHIPPED / "decoy.npz").act(obs)
    np.testing.assert_allclose(actor.act(obs), expected, rtol=0, atol=1e-5)
    np.testing.assert_allclose(actor.act(obs[3]), expected[3], rtol=0, atol=1e-5)


def test_an_onnx_actor_pickles_as_its_file(exported: Path):
    """What ``evaluate --workers N`` sends to its Ray workers: the file's bytes, the session built again there."""
    actor = OnnxPolicy.load(exported / "detect.onnx")
    again = pickle.loads(pickle.dumps(actor))
    obs = observations(50, seed=1)
    assert again.role is Role.DETECT and np.array_equal(again.act(obs), actor.act(obs))


# ------------------------------------------------------------------------------ the export


def test_export_writes_the_three_actors_and_a_manifest_that_checks(exported: Path, tmp_path: Path, capsys):
    assert sorted(p.name for p in exported.iterdir()) == [MANIFEST, "decoy.onnx", "detect.onnx", "strike.onnx"]
    assert check_command(exported) == f"{exported}: 3 files match {MANIFEST}"
    model = onnx.load(exported / "strike.onnx")
    props = {p.key: p.value for p in model.metadata_props}
    assert {k: props[k] for k in REQUIRED} == {"role": "strike", "observation_mode": "route", "action_repeat": "10"}
    assert props["source"] == "strike.npz" and len(props["source_sha256"]) == 64
    assert [node.op_type for node in model.graph.node] == ["Gemm", "Relu", "Gemm", "Relu", "Gemm", "Slice", "Tanh"]
    assert model.opset_import[0].version == 17
    # The same team exported again gives the same bytes; the npz export (the default) is unchanged by the option.
    assert run(export_main, [str(SHIPPED), "--format", "onnx", "--out", str(tmp_path / "again")]) == 0
    assert read_manifest(tmp_path / "again") == read_manifest(exported)
    assert capsys.readouterr().out.count("wrote ") == 4


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["{models}", "--out", "{tmp}/x"], "--out is for --format onnx"),
        (["{models}", "--format", "onnx"], "give it with --out DIR2"),
        (["{models}", "{models}", "--format", "onnx", "--out", "{tmp}/x"], "one models directory"),
        (["{models}", "--format", "onnx", "--out", "{models}"], "ONNX actors go to a directory of their own"),
        (["{tmp}", "--format", "onnx", "--out", "{tmp}/x"], "no <role>.pt or <role>.npz here"),
        (["{tmp}/nowhere", "--format", "onnx", "--out", "{tmp}/x"], "nowhere: models directory not found"),
        (["{team}", "--format", "onnx", "--out", "{tmp}/x"], "holds ONNX actors already"),
    ],
    ids=["out-without-onnx", "onnx-without-out", "two-dirs", "into-the-models", "empty", "no-dir", "from-onnx"],
)
def test_export_bad_use_is_one_line(team: Path, tmp_path: Path, capsys, argv: list[str], needle: str):
    models = tmp_path / "models"
    models.mkdir()
    for role in ROLES:
        shutil.copy(SHIPPED / f"{role.value}.npz", models / f"{role.value}.npz")
    filled = [a.format(models=models, tmp=tmp_path / "empty", team=team) for a in argv]
    (tmp_path / "empty").mkdir()
    assert run(export_main, filled) == 2
    assert needle in one_error_line(capsys.readouterr().err)


# ------------------------------------------------------------------------------ files that do not fit


def rewrite(path: Path, change: Callable[[onnx.ModelProto], None]) -> None:
    """Change the model in ``path`` and record it in the manifest again (so the file itself, not its digest, is what
    the loader meets)."""
    model = onnx.load(path)
    change(model)
    path.write_bytes(model.SerializeToString())
    record(path.parent, [path.name])


def corrupt(path: Path) -> None:
    """Bytes that are no ONNX model, recorded in the manifest."""
    path.write_bytes(b"garbage")
    record(path.parent, [path.name])


def set_meta(**entries: str | None) -> Callable[[onnx.ModelProto], None]:
    def change(model: onnx.ModelProto) -> None:
        props = {p.key: p.value for p in model.metadata_props}
        props.update(entries)
        del model.metadata_props[:]
        helper.set_model_props(model, {k: v for k, v in props.items() if v is not None})

    return change


def foreign(model: onnx.ModelProto) -> None:
    """Another framework's model: a 24 -> 2 graph of its own, no metadata."""
    node = helper.make_node("Identity", ["x"], ["y"])
    graph = helper.make_graph(
        [node],
        "foreign",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 24])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 24])],
    )
    model.CopyFrom(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=8))


def two_outputs(model: onnx.ModelProto) -> None:
    model.graph.output.append(helper.make_tensor_value_info("mean", TensorProto.FLOAT, ["n", 2]))


def wide_action(model: onnx.ModelProto) -> None:
    """The whole last layer (mean and log-std) as the action: 4 values per observation, not 2."""
    model.graph.initializer.append(numpy_helper.from_array(np.array([4], dtype=np.int64), "all"))
    model.graph.node[5].input[2] = "all"  # Slice(z2, start 0, end 4, axis 1)
    model.graph.output[0].type.tensor_type.shape.dim[1].dim_param = "m"


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda p: corrupt(p), "not a loadable ONNX model"),
        (lambda p: rewrite(p, foreign), "no 'role' in the model's metadata_props"),
        (lambda p: rewrite(p, set_meta(observation_mode=None)), "no 'observation_mode' in the model's metadata"),
        (lambda p: rewrite(p, set_meta(action_repeat=None)), "no 'action_repeat'"),
        (lambda p: rewrite(p, set_meta(role="strike")), "for the strike UAV, not the detect"),
        (lambda p: rewrite(p, set_meta(observation_mode="paper")), "takes 24 observation values, the 'paper'"),
        (lambda p: rewrite(p, set_meta(observation_mode="psychic")), "observation_mode 'psychic' is not"),
        (lambda p: rewrite(p, set_meta(action_repeat="0.5")), "action_repeat '0.5' is not a positive integer"),
        (lambda p: rewrite(p, two_outputs), "1 inputs and 2 outputs"),
        (lambda p: rewrite(p, wide_action), "not the action's (2,)"),
        (lambda p: p.unlink(), "detect.onnx: listed in"),
    ],
    ids=[
        "corrupt",
        "foreign",
        "no-mode",
        "no-repeat",
        "role",
        "obs-size",
        "mode",
        "repeat",
        "outputs",
        "action-size",
        "missing",
    ],
)
def test_a_file_that_does_not_fit_is_one_line_before_any_mission(team: Path, capsys, damage, message: str):
    damage(team / "detect.onnx")
    with pytest.raises(CheckpointError, match=re.escape(message)) as err:
        load_actor(pilot_file(team, Role.DETECT), Role.DETECT)
    assert "\n" not in str(err.value) and str(team / "detect.onnx") in str(err.value)
    # evaluate and fly refuse the directory in that line, exit code 2, before the first mission
    assert run(evaluate_main, ["--models", str(team), "--episodes", "1", "--no-progress"]) == 2
    assert message in one_error_line(capsys.readouterr().err)
    assert fly_main(["--scenario", str(STRIKE), "--models", str(team), "--no-progress"]) == 2
    assert message in one_error_line(capsys.readouterr().err)


def test_a_tampered_onnx_is_refused_in_one_line(team: Path, capsys):
    data = bytearray((team / "strike.onnx").read_bytes())
    data[len(data) // 2] ^= 0x01  # a weight's bit: the file still loads, and would fly another actor
    (team / "strike.onnx").write_bytes(bytes(data))
    expected = f"{team / 'strike.onnx'}: its sha256 differs from {team / MANIFEST}"
    assert run(evaluate_main, ["--models", str(team), "--episodes", "1", "--no-progress"]) == 2
    assert expected in one_error_line(capsys.readouterr().err)
    assert fly_main(["--scenario", str(STRIKE), "--models", str(team), "--no-progress"]) == 2
    assert expected in one_error_line(capsys.readouterr().err)
    argv = ["--connect", "udpout:127.0.0.1:9", "--role", "strike", "--model", str(team / "strike.onnx")]
    assert companion_main([*argv, "--scenario", str(STRIKE), "--timeout-s", "2"]) == 2
    assert expected in one_error_line(capsys.readouterr().err)


def test_the_companion_refuses_another_roles_onnx_in_one_line(team: Path, capsys):
    argv = ["--connect", "udpout:127.0.0.1:9", "--role", "decoy", "--model", str(team / "strike.onnx")]
    assert companion_main([*argv, "--scenario", str(STRIKE), "--timeout-s", "2"]) == 2
    assert "ONNX actor is for the strike UAV, not the decoy" in one_error_line(capsys.readouterr().err)


def test_a_directory_of_two_formats_or_a_missing_role_is_one_line(team: Path):
    (team / "strike.onnx").unlink()
    (team / MANIFEST).unlink()  # (with it, the manifest names the missing file first)
    with pytest.raises(CheckpointError, match="strike.onnx: ONNX actor not found"):
        load_policy(team, Role.STRIKE)
    shutil.copy(SHIPPED / "decoy.npz", team / "decoy.npz")
    with pytest.raises(CheckpointError, match="ONNX actors beside decoy.npz: one format per models directory"):
        pilot_file(team, Role.DECOY)


def test_without_onnxruntime_the_install_line(exported: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setitem(sys.modules, "onnxruntime", None)  # import onnxruntime now raises ImportError
    with pytest.raises(CheckpointError, match=r"needs onnxruntime \(pip install -e '.\[onnx\]'\)"):
        OnnxPolicy.load(exported / "decoy.onnx")


def test_commands_that_fly_no_onnx_never_import_onnxruntime(exported: Path):
    code = (
        "import sys\n"
        "from pathlib import Path\n"
        "import tssac_core.evaluate, tssac_core.deploy.export, mavlink_bridge.fly.cli, mavlink_bridge.companion.cli\n"
        "import mavlink_bridge.companion.held_pilot as c\n"
        "from tssac_core.sim.scenario import Role\n"
        f"c.policy_pilot(Path({str(SHIPPED / 'strike.npz')!r}), Role.STRIKE)\n"
        "print('onnxruntime' in sys.modules, 'onnx' in sys.modules)\n"
        f"pilot = c.policy_pilot(Path({str(exported / 'strike.onnx')!r}), Role.STRIKE)\n"
        "print(type(pilot.policy).__name__, 'torch' in sys.modules, 'onnx' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "False", "OnnxPolicy", "False", "False"]


# ------------------------------------------------------------------------------ flown


def test_evaluate_flies_the_onnx_team_to_the_same_figures(exported: Path, tmp_path: Path):
    figures = {}
    for name, models in (("pt", SHIPPED), ("onnx", exported)):
        path = tmp_path / f"{name}.json"
        argv = ["--models", str(models), "--episodes", "3", "--seed", "2262001", "--no-progress", "--json", str(path)]
        assert run(evaluate_main, argv) == 0
        figures[name] = json.loads(path.read_text())
    pt, ox = figures["pt"], figures["onnx"]
    for key in ("success_rate", "mean_cost", "success_interval95", "mean_cost_interval95", "episodes"):
        assert ox[key] == pt[key], key
    for role in pt["roles"]:
        for key, value in pt["roles"][role].items():
            # The returns sum 0.1 s rewards along paths whose actions differ by ~1e-6: equal to ~1e-13.
            assert ox["roles"][role][key] == pytest.approx(value, rel=1e-9), (role, key)
    assert ox["worst_missions"] == pt["worst_missions"]


@pytest.mark.sitl
@pytest.mark.timeout(300)
def test_fly_flies_the_onnx_team_over_mavlink(exported: Path, tmp_path: Path):
    out = tmp_path / "fly.json"
    t0 = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-m", "mavlink_bridge.fly", "--models", str(exported), "--scenario", str(STRIKE)]
        + ["--json", str(out), "--logs", str(tmp_path / "logs"), "--no-progress"],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**__import__("os").environ, "PYTHONPATH": str(REPO)},
        timeout=280,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    results = json.loads(out.read_text())
    mission = results["missions"][0]
    assert results["success_rate"] == 1.0 and results["pilot"] == str(exported) and mission["success"]
    assert all(c["status"] == "success" and c["exit_code"] == 0 for c in mission["companions"].values())
    assert mission["steps"] == pytest.approx(2542, abs=30)  # the numpy actors fly this mission in 2,542 steps
    flown = "".join(p.read_text() for p in (tmp_path / "logs").rglob("*.log"))
    for role in ROLES:  # each companion was handed its .onnx
        assert str(exported / f"{role.value}.onnx") in flown, role
    print(f"ONNX team, strike mission: {time.monotonic() - t0:.1f} s wall, {mission['sim_time_s']:.0f} s simulated")


def test_the_benchmark_runs_and_writes_its_json_where_asked(tmp_path: Path):
    out = tmp_path / "bench.json"
    argv = [sys.executable, str(REPO / "benchmarks" / "bench_onnx.py"), "--calls", "200", "--batch", "10"]
    done = subprocess.run([*argv, "--json", str(out)], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert done.returncode == 0, done.stderr
    figures = json.loads(out.read_text())
    assert figures["calls"] == 200 and figures["numpy"]["median_us"] > 0 and figures["onnx"]["p99_us"] > 0
    assert figures["max_abs_action_difference"] < 1e-5 and figures["threads_started_by_onnxruntime"] in (0, None)
    assert "onnx / numpy: median" in done.stdout and sorted(p.name for p in tmp_path.iterdir()) == ["bench.json"]
