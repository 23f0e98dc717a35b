"""Shared fixtures: scenario paths and small helpers."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ROOT / "scenarios"


@pytest.fixture(scope="session")
def strike_path() -> Path:
    return SCENARIOS / "strike.yaml"


@pytest.fixture(scope="session")
def random_path() -> Path:
    return SCENARIOS / "random.yaml"
