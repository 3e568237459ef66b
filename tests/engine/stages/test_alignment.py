"""Stage 2 DP (thesis 4.5.2, eq. 4.11): exact optimum, monotone, ends pinned."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.errors import InvalidInput
from engine.stages.alignment import band_mask, dp_path, rotation_samples, window_size


def brute_force(cost, window, start, end, min_step=1):
    n_v, n_r = cost.shape
    best, arg = np.inf, None
    for mid in itertools.product(range(n_r), repeat=n_v - 2):
        path = (start, *mid, end) if n_v > 1 else (start,)
        steps = np.diff(path)
        if np.any(steps < min_step) or np.any(steps > window):
            continue
        c = cost[np.arange(n_v), path].sum()
        if c < best:
            best, arg = c, path
    return best, arg


def test_known_optimum_hand_built():
    cost = np.ones((4, 8))
    cost[[0, 1, 2, 3], [0, 3, 4, 7]] = 0.0
    C, total = dp_path(cost, window=3)
    assert C.tolist() == [0, 3, 4, 7]
    assert total == 0.0


def test_window_limits_the_step():
    cost = np.ones((4, 8))
    cost[1, 6] = 0.0  # needs a step of 6 from frame 0
    C, _ = dp_path(cost, window=3)
    assert np.all(np.diff(C) <= 3)


@settings(max_examples=60, deadline=None)
@given(
    n_v=st.integers(2, 4),
    n_r=st.integers(4, 7),
    window=st.integers(1, 4),
    seed=st.integers(0, 10_000),
    min_step=st.sampled_from([0, 1]),
)
def test_dp_equals_brute_force(n_v, n_r, window, seed, min_step):
    cost = np.random.default_rng(seed).random((n_v, n_r))
    best, arg = brute_force(cost, window, 0, n_r - 1, min_step)
    if arg is None:
        with pytest.raises(InvalidInput, match="no monotone path"):
            dp_path(cost, window=window, min_step=min_step)
        return
    C, total = dp_path(cost, window=window, min_step=min_step)
    assert C[0] == 0 and C[-1] == n_r - 1
    assert np.all(np.diff(C) >= min_step) and np.all(np.diff(C) <= window)
    assert total == pytest.approx(best)
    assert cost[np.arange(n_v), C].sum() == pytest.approx(total)


def test_floating_ends_find_a_cheaper_start():
    cost = np.ones((3, 10))
    cost[0, 2] = cost[1, 4] = cost[2, 7] = 0.0
    C, total = dp_path(cost, window=3, float_start=2, float_end=2)
    assert C.tolist() == [2, 4, 7] and total == 0.0


def test_band_mask_and_window():
    m = band_mask(5, 9, 1.0)
    assert m[0, 0] and m[-1, -1] and not m[0, 5]
    assert window_size(10, 581, 138) == int(np.ceil(10 * 580 / 137))
    assert rotation_samples((0.0, 10.0), (5.0,)).shape == (4, 3, 3)


def test_dp_validation():
    with pytest.raises(InvalidInput, match="cost must be"):
        dp_path(np.ones(3), window=2)
    with pytest.raises(InvalidInput, match="window must be"):
        dp_path(np.ones((2, 3)), window=0)
    with pytest.raises(InvalidInput, match="start and end"):
        dp_path(np.ones((2, 3)), window=2, start=3)
    with pytest.raises(InvalidInput, match="min_step"):
        dp_path(np.ones((2, 3)), window=2, min_step=2)
    with pytest.raises(InvalidInput, match="float_start"):
        dp_path(np.ones((2, 3)), window=2, float_start=-1)
    with pytest.raises(InvalidInput, match="no monotone path"):
        dp_path(np.ones((5, 3)), window=2)
