"""The test suite's own scheduling: ``--dist loadgroup`` (pyproject.toml's addopts) keeps the tests that share a
resource in one test process (one Ray at a time, the smoke grid trained once; tests/test_experiments.py,
tests/test_ray.py). pytest-xdist hands a test's ``xdist_group`` to its scheduler as a suffix of the test's node id;
pytest 9.2 keeps the id elsewhere, and then every group mark silently does nothing (pyproject.toml pins below it)."""

from __future__ import annotations

import pytest

pytestmark = pytest.mark.xdist_group("suite_groups")


def test_xdist_group_marks_reach_the_scheduler(request: pytest.FixtureRequest) -> None:
    if not getattr(request.config.option, "loadgroup", False):
        pytest.skip("not an xdist worker under --dist loadgroup")
    assert request.node.nodeid.endswith("@suite_groups"), request.node.nodeid
