"""Fixtures of the bench tests: tiny aligned datasets (80x60, 3 frames) built with AlignedDatasetWriter."""
from __future__ import annotations

import pytest

from bench.metrics import MetricConfig
from tests.bench.helpers import make_dataset

#: 80x60 pixels at f = 70 px are ~17 mm wide at 1.2 m: a 40 mm radius gives real plane fits.
SMALL_CONFIG = MetricConfig(radius_m=0.04)


@pytest.fixture(scope="session")
def datasets(tmp_path_factory):
    """Two aligned datasets: A simulated (truth, ROI, colour), B real-like (no truth), one sequence each."""
    root = tmp_path_factory.mktemp("aligned")
    a = make_dataset(root / "A", name="A", sequence="seq-a", seed=1)
    b = make_dataset(root / "B", name="B", sequence="seq-b", truth=False, seed=2)
    return root, a, b


@pytest.fixture(scope="session")
def empty_reference_dataset(tmp_path_factory):
    return make_dataset(tmp_path_factory.mktemp("empty") / "E", name="E", empty_reference=True)
