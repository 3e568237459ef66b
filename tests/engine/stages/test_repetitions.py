"""Repetitions: the reference found as a subsequence of the video, as often as it occurs."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.errors import InvalidInput
from engine.stages.repetitions import find_repetitions


def _path(length: int, n_c: int) -> np.ndarray:
    """A linear path through every column in ``length`` frames."""
    return np.round(np.arange(length) * (n_c - 1) / (length - 1)).astype(int)


def _video(reps: list[tuple[int, int]], n_v: int, n_c: int, rng) -> np.ndarray:
    """Cost (n_v, n_c): about 0 along a linear path through every column for each (start,
    length) repetition, about 1 elsewhere."""
    cost = 1.0 + 0.05 * rng.random((n_v, n_c))
    for start, length in reps:
        for k, c in enumerate(_path(length, n_c)):
            cost[start + k, c] = 0.05 * rng.random()
    return cost


def test_three_repetitions_with_idle_time_between(rng):
    reps = [(5, 20), (32, 15), (60, 25)]
    cost = _video(reps, 95, 12, rng)
    found = find_repetitions(cost, window=3, idle_cost=0.5)
    assert [(r.start, r.end) for r in found] == [(s, s + n) for s, n in reps]
    assert all(r.mean_cost < 0.05 for r in found)


def test_one_clean_performance_covers_the_whole_video(rng):
    cost = _video([(0, 40)], 40, 10, rng)
    found = find_repetitions(cost, window=3, idle_cost=0.5)
    assert [(r.start, r.end) for r in found] == [(0, 40)]


def test_frames_like_no_reference_posture_are_idle(rng):
    cost = _video([(10, 20)], 40, 8, rng)
    cost[:10] = 0.9  # something else before (a walk in)
    cost[30:] = 0.9  # and after
    (r,) = find_repetitions(cost, window=3, idle_cost=0.5)
    assert (r.start, r.end) == (10, 30)


def test_holding_the_first_posture_stays_in_the_repetition(rng):
    # the reference itself may hold a posture: only frames that match nothing are idle
    cost = _video([(10, 20)], 30, 8, rng)
    cost[:10, 0] = 0.01
    (r,) = find_repetitions(cost, window=3, idle_cost=0.5)
    assert (r.start, r.end) == (0, 30)


def test_nothing_like_the_reference_finds_nothing(rng):
    cost = 1.0 + rng.random((50, 10))
    assert find_repetitions(cost, window=3, idle_cost=0.5) == []


def test_a_repetition_cut_by_the_end_of_the_video_is_not_counted(rng):
    cost = _video([(5, 20)], 35, 10, rng)
    cost[28:, :] = 1.0
    cost[28, 0] = 0.0  # a new one starts ...
    cost[29:, 1:4] = 0.0  # ... and is cut off: reaching the end would cost 1 a frame
    found = find_repetitions(cost, window=3, idle_cost=0.1)
    assert [(r.start, r.end) for r in found] == [(5, 25)]


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 3))
def test_found_repetitions_are_ordered_disjoint_and_complete(seed, n):
    rng = np.random.default_rng(seed)
    lengths = rng.integers(8, 16, n)
    gaps = rng.integers(0, 6, n + 1)
    starts = np.cumsum(np.r_[gaps[0], (lengths + gaps[1:])[:-1]])
    n_v = int(starts[-1] + lengths[-1] + gaps[-1])
    cost = _video(list(zip(starts.tolist(), lengths.tolist(), strict=True)), n_v, 6, rng)
    found = find_repetitions(cost, window=3, idle_cost=0.5)
    assert len(found) == n
    for a, b in zip(found, found[1:], strict=False):
        assert a.end <= b.start
    assert all(r.end - r.start >= 6 / 3 for r in found)


def test_validation():
    with pytest.raises(InvalidInput, match="cost must be"):
        find_repetitions(np.zeros((5, 1)), window=2, idle_cost=0.5)
    with pytest.raises(InvalidInput, match="window"):
        find_repetitions(np.zeros((5, 4)), window=0, idle_cost=0.5)
    with pytest.raises(InvalidInput, match="idle_cost"):
        find_repetitions(np.zeros((5, 4)), window=2, idle_cost=float("nan"))
