"""The exported actor (<role>.npz): same actions as the torch policy, flown without importing torch,
never shadowing a retrained .pt, and one clear line for a bad file."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tssac_core.common.errors import CheckpointError
from tssac_core.deploy.export import compact_checkpoint, export_actor
from tssac_core.deploy.numpy_actor import NumpyPolicy, load_actor, pilot_file
from tssac_core.deploy.policy import Policy
from tssac_core.sim.scenario import ROLES, Role

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = ROOT / "models" / "tssac"


@pytest.fixture()
def models(tmp_path: Path) -> Path:
    """A models directory holding copies of the shipped checkpoints and fresh exports of them."""
    d = tmp_path / "models"
    d.mkdir()
    for role in ROLES:
        shutil.copy(SHIPPED / f"{role.value}.pt", d / f"{role.value}.pt")
        export_actor(d / f"{role.value}.pt")
    return d


@pytest.mark.parametrize("role", ROLES, ids=lambda r: r.value)
def test_exported_actor_acts_like_the_torch_policy(models: Path, role: Role):
    torch_policy = Policy.load(models / f"{role.value}.pt", role)
    numpy_policy = NumpyPolicy.load(models / f"{role.value}.npz", role)
    assert (numpy_policy.observation_mode, numpy_policy.action_repeat, numpy_policy.obs_dim) == (
        torch_policy.observation_mode,
        torch_policy.action_repeat,
        torch_policy.info.obs_dim,
    )
    obs = np.random.default_rng(1).uniform(-1.5, 1.5, (500, numpy_policy.obs_dim)).astype(np.float32)
    batch = numpy_policy.act(obs)
    assert batch.shape == (500, 2) and batch.dtype == np.float64
    # float32 sums over 128-wide layers in another order: up to ~1e-5 apart (the shipped detect 1.006e-5 once in 1,000)
    np.testing.assert_allclose(batch, torch_policy.act(obs), atol=5e-5)
    np.testing.assert_allclose(numpy_policy.act(obs[7]), torch_policy.act(obs[7]), atol=1e-5)
    assert np.abs(batch).max() > 0.5, "the actions should not all be near zero (is tanh applied to the right half?)"
    with pytest.raises(ValueError, match="takes"):
        numpy_policy.act(obs[:, :-1])


def test_the_companion_flies_an_export_without_importing_torch(models: Path):
    code = (
        "import sys\n"
        "import mavlink_bridge.companion.held_pilot as c\n"
        "from tssac_core.sim.scenario import Role\n"
        f"pilot = c.policy_pilot(__import__('pathlib').Path({str(models / 'strike.npz')!r}), Role.STRIKE)\n"
        "print(type(pilot.policy).__name__, 'torch' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["NumpyPolicy", "False"]


def test_pilot_file_prefers_a_fresh_export_and_never_a_stale_one(models: Path, caplog: pytest.LogCaptureFixture):
    assert pilot_file(models, Role.DECOY) == models / "decoy.npz"
    # Retrain (here: overwrite with another role's checkpoint bytes): the old export must not fly.
    shutil.copy(SHIPPED / "detect.pt", models / "decoy.pt")
    assert pilot_file(models, Role.DECOY) == models / "decoy.pt"
    assert "exported from another decoy.pt" in caplog.text
    (models / "detect.pt").unlink()  # an export alone is enough
    assert pilot_file(models, Role.DETECT) == models / "detect.npz"
    (models / "strike.npz").unlink()
    assert pilot_file(models, Role.STRIKE) == models / "strike.pt"
    assert type(load_actor(models / "strike.pt", Role.STRIKE)).__name__ == "Policy"


def test_compacting_a_checkpoint_refreshes_its_export(models: Path):
    import torch

    from tssac_core.deploy.policy import read_checkpoint, torch_save_atomic

    pt = models / "decoy.pt"
    # A checkpoint as training writes it carries the learner's state (critics, optimiser moments): stand one in.
    torch_save_atomic({**read_checkpoint(pt), "learner": {"q_r": torch.zeros(20_000)}}, pt)
    export_actor(pt)
    before = NumpyPolicy.load(models / "decoy.npz").meta["source_sha256"]
    size_before, size_after = compact_checkpoint(pt)
    assert size_after < size_before, "the learner state should be dropped"
    assert pilot_file(models, Role.DECOY) == models / "decoy.npz", "compaction rewrote the .pt: the export must follow"
    assert NumpyPolicy.load(models / "decoy.npz").meta["source_sha256"] != before


def _rewrite(path: Path, **change) -> None:
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays["meta"]))
    for key, value in change.items():
        if key.startswith("meta_"):
            meta[key[5:]] = value
        elif value is None:
            arrays.pop(key)
        else:
            arrays[key] = value
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez(path, **arrays)


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda p: p.write_bytes(b"garbage"), "not a readable .npz file"),
        (lambda p: p.unlink(), "exported actor not found"),
        (lambda p: np.savez(p, w0=np.zeros(3)), "no readable meta"),
        (lambda p: _rewrite(p, meta_format="something-else"), "not an exported TSSAC actor"),
        (lambda p: _rewrite(p, meta_format_version=99), "format version 99"),
        (lambda p: _rewrite(p, meta_observation_mode="psychic"), "metadata is damaged"),
        (lambda p: _rewrite(p, meta_obs_dim=5), "does not fit the 'route' observation"),
        (lambda p: _rewrite(p, w1=np.zeros((3, 3), np.float32)), "layer 1 is missing or not 128x128"),
        (lambda p: _rewrite(p, b2=None), "layer 2 is missing"),
        (lambda p: _rewrite(p, b0=np.full(128, np.nan, np.float32)), "non-finite weights"),
    ],
    ids=[
        "garbage",
        "missing",
        "no-meta",
        "format",
        "version",
        "mode",
        "obs-size",
        "layer-shape",
        "layer-missing",
        "nan",
    ],
)
def test_a_bad_export_is_one_clear_line(models: Path, damage, message: str):
    path = models / "detect.npz"
    damage(path)
    with pytest.raises(CheckpointError, match=message) as err:
        NumpyPolicy.load(path)
    assert "\n" not in str(err.value) and str(path) in str(err.value)


def test_an_export_for_another_role_is_refused(models: Path):
    with pytest.raises(CheckpointError, match="for the detect UAV, not the strike"):
        NumpyPolicy.load(models / "detect.npz", Role.STRIKE)


def test_export_command(models: Path, tmp_path: Path):
    for npz in models.glob("*.npz"):
        npz.unlink()
    out = subprocess.run(
        [sys.executable, "-m", "tssac_core.deploy.export", str(models)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.count("wrote ") == 3 and "actor 24->128->128->4" in out.stdout
    assert all(pilot_file(models, r).suffix == ".npz" for r in ROLES)
    bad = subprocess.run(
        [sys.executable, "-m", "tssac_core.deploy.export", str(tmp_path / "nothing")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert bad.returncode == 2 and bad.stderr.strip().count("\n") == 0 and "not a role checkpoint" in bad.stderr
