"""Shared fixtures: paths to the shared data beside the clone."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
CMU = SHARED / "data" / "cmu"
BENCH_CASES = SHARED / "bench" / "cases"


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


@pytest.fixture
def cmu_bvh() -> Path:
    path = CMU / "64_29.bvh"
    if not path.exists():
        pytest.skip("../shared/data/cmu is not beside the clone")
    return path
