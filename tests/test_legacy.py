"""Files written by older versions still load: the shipped models and the grid's runs (tssac_core.train.legacy)."""

from __future__ import annotations

import pickletools
import zipfile
from pathlib import Path

import numpy as np
import pytest

from tssac_core.deploy.policy import CheckpointInfo, Policy
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.scenario import ROLES, Role
from tssac_core.train.algorithms import Algo

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = ROOT / "models" / "tssac"


def pickled_globals(path: Path) -> set[str]:
    """``module.name`` of every class or function a torch checkpoint's pickle refers to."""
    with zipfile.ZipFile(path) as z:
        data = z.read(next(n for n in z.namelist() if n.endswith("data.pkl")))
    ops = list(pickletools.genops(data))
    found = set()
    for i, (op, arg, _) in enumerate(ops):
        if op.name == "GLOBAL":
            found.add(str(arg).replace(" ", "."))
        elif op.name == "STACK_GLOBAL":
            found.add(f"{ops[i - 2][1]}.{ops[i - 1][1]}")
    return found


@pytest.mark.skipif(not SHIPPED.is_dir(), reason="no shipped models")
@pytest.mark.parametrize("role", ROLES, ids=lambda r: r.value)
def test_shipped_checkpoints_name_no_module_of_the_package_and_load(role):
    path = SHIPPED / f"{role.value}.pt"
    names = pickled_globals(path)
    assert any(n.startswith("torch.") for n in names)  # the scan reads the pickle
    assert not [n for n in names if n.startswith("tssac_core")], "a module path in a pickle breaks on every move"
    policy = Policy.load(path, role)
    assert policy.act(np.zeros(policy.info.obs_dim)).shape == (2,)


def test_the_grid_runs_checkpoints_name_no_module_of_the_package():
    runs = sorted((ROOT / "results" / "runs").glob("*/*.pt"))
    if not runs:
        pytest.skip("no grid runs here")
    offenders = [str(p) for p in runs if any(n.startswith("tssac_core") for n in pickled_globals(p))]
    assert not offenders


def test_a_checkpoint_stores_the_algorithm_as_a_plain_string():
    """``--algo`` is an enum; a checkpoint that pickled it would name ``tssac_core.train.algorithms`` (as the
    first runs of the hard-layouts recipe did, fixed in the shipped files by writing the name)."""
    info = CheckpointInfo(Role.DECOY, Algo.TSSAC, ObservationMode.ROUTE, 24, 2, (128, 128), "d", {}, {}, 10)
    assert type(info.fields()["algo"]) is str and info.fields()["algo"] == "tssac"
