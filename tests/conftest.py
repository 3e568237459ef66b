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
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run"]  # fmt: skip


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


@pytest.fixture
def cmu_bvh() -> Path:
    path = CMU / "64_29.bvh"
    if not path.exists():
        pytest.skip("../shared/data/cmu is not beside the clone")
    return path


@pytest.fixture(scope="session")
def browser():
    """One headless Debian Chromium for the whole session.

    Playwright's sync API refuses to start inside a running one, so every browser test
    (tests/browser, tests/web) shares this instance.
    """
    if not CHROMIUM.exists():
        pytest.skip("Debian chromium is not installed at /usr/bin/chromium")
    sync_api = pytest.importorskip("playwright.sync_api")
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield b
        b.close()
