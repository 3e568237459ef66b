"""Repetitions: the reference found as a subsequence of the video, as often as it occurs."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.errors import InvalidInput
from engine.stages.repetitions import excursions, find_repetitions, performances


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


# ---- excursions: repetitions from the keypoints' own motion
STAND = np.array([
    [50, 100], [55, 100], [55, 140], [55, 180], [45, 100], [45, 140], [45, 180],
    [50, 85], [50, 70], [60, 60], [62, 80], [62, 100], [40, 60], [38, 80], [38, 100],
    [50, 58], [50, 40],
], dtype=float)  # fmt: skip


def _squat_frames(depth: np.ndarray) -> np.ndarray:
    """(T', 17, 2) keypoints of a front-facing squat: hips and everything above them drop by
    ``depth`` (0 standing, 1 deep) while the knees come forward and the ankles stay."""
    kp = np.repeat(STAND[None], len(depth), axis=0)
    upper = [0, 1, 4, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16]
    kp[:, upper, 1] += 40 * depth[:, None]
    kp[:, [2, 5], 1] += 15 * depth[:, None]
    kp[:, [2, 5], 0] += np.array([8, -8]) * depth[:, None]
    return kp


def _squats(spans: list[tuple[int, int]], n: int) -> np.ndarray:
    depth = np.zeros(n)
    for a, b in spans:
        depth[a:b] = np.sin(np.linspace(0, np.pi, b - a))
    return depth


def test_excursions_finds_each_whole_squat_not_the_cut_one(rng):
    fps = 10.0
    depth = _squats([(10, 30), (45, 65)], 100)
    depth[85:] = np.sin(np.linspace(0, 0.6 * np.pi, 15))  # the third is cut near its bottom
    kp = _squat_frames(depth) + rng.normal(0, 0.5, (100, 17, 2))
    swapped = rng.random(100) < 0.4  # the detector swaps left and right in 40 % of frames
    pairs = [(1, 4), (2, 5), (3, 6), (9, 12), (10, 13), (11, 14)]
    for a, b in pairs:
        kp[swapped, a], kp[swapped, b] = kp[swapped, b].copy(), kp[swapped, a].copy()
    reps = excursions(kp, STAND, fps)
    found = [t for r in reps for t in (r.start, r.end)]
    assert found == pytest.approx([13, 27, 48, 62], abs=2)


def test_excursions_ignores_a_short_blip_and_a_still_video(rng):
    fps = 10.0
    depth = _squats([(10, 30), (45, 65), (75, 79)], 100)  # the last: a 0.4 s dip, re-racking
    reps = excursions(_squat_frames(depth), STAND, fps)
    assert len(reps) == 2
    still = _squat_frames(np.zeros(50)) + rng.normal(0, 0.5, (50, 17, 2))
    assert excursions(still, STAND, fps) == []  # keypoint noise is no motion


def test_the_rest_posture_comes_from_the_reference_not_the_calmest_frames():
    """At 5 fps a performer dwells as long at the bottom of a squat as standing; the rest
    posture must still be standing because the reference starts standing."""
    fps = 5.0
    depth = np.zeros(60)
    for a in (5, 25, 45):  # down fast, hold the bottom, up fast
        depth[a : a + 2] = [0.5, 1.0]
        depth[a + 2 : a + 9] = 1.0
        depth[a + 9 : a + 11] = [1.0, 0.5]
    reps = excursions(_squat_frames(depth), STAND, fps)
    found = [t for r in reps for t in (r.start, r.end)]
    assert found == pytest.approx([5, 16, 25, 36, 45, 56], abs=1)


# ---- performances: the excursions grouped as the reference's own, with its rest around them
def _reference_squat(fps: float) -> np.ndarray:
    """(T, 17, 2): 1 s standing, a 2 s squat, 1 s standing."""
    n = int(4 * fps)
    return _squat_frames(_squats([(int(fps), int(3 * fps))], n))


def test_performances_cut_each_squat_of_a_set_with_the_reference_rest_around_it(rng):
    ref_fps, fps = 40.0, 10.0
    depth = _squats([(20, 40), (70, 90), (120, 140)], 160)  # three squats, as slow as the ref
    kp = _squat_frames(depth) + rng.normal(0, 0.5, (160, 17, 2))
    found = performances(kp, _reference_squat(ref_fps), fps, ref_fps)
    assert found.per_performance == 1
    assert len(found.found) == 3
    for r, (a, b) in zip(found.found, [(20, 40), (70, 90), (120, 140)], strict=True):
        # the whole squat, with about the reference's 1 s (10 frames) of rest before it
        assert r.start <= a and r.end >= b
        assert a - r.start == pytest.approx(10, abs=3)
    assert all(a.end <= b.start for a, b in zip(found.found, found.found[1:], strict=False))
    doc = found.to_dicts(fps, analysed=0, offset=5)
    assert [d["analysed"] for d in doc] == [True, False, False]
    assert doc[0]["start"] == found.found[0].start + 5
    assert doc[0]["start_s"] == pytest.approx(doc[0]["start"] / fps, abs=0.01)


def test_performances_scale_the_rest_with_the_performers_pace(rng):
    ref_fps, fps = 40.0, 10.0
    depth = _squats([(20, 60), (100, 140)], 170)  # each squat takes twice the reference's time
    found = performances(_squat_frames(depth), _reference_squat(ref_fps), fps, ref_fps)
    first = found.found[0]
    assert first.start == pytest.approx(20 + 2 - 20, abs=3)  # 1 s of rest at half the pace
    assert first.end == pytest.approx(80, abs=3)  # halfway to the next squat


def test_one_performance_or_none_is_left_to_stage_2(rng):
    ref_fps, fps = 40.0, 10.0
    one = _squat_frames(_squats([(10, 30)], 45))
    assert performances(one, _reference_squat(ref_fps), fps, ref_fps).found == ()
    still = _squat_frames(np.zeros(45)) + rng.normal(0, 0.5, (45, 17, 2))
    assert performances(still, _reference_squat(ref_fps), fps, ref_fps).found == ()


def test_a_reference_that_never_leaves_its_first_posture_finds_nothing():
    ref = _squat_frames(np.zeros(80))
    kp = _squat_frames(_squats([(10, 30), (45, 65)], 80))
    found = performances(kp, ref, 10.0, 40.0)
    assert found.found == () and found.per_performance == 0


def test_performances_validation():
    ref = _reference_squat(40.0)
    with pytest.raises(InvalidInput, match="must be \\(T, 17, 2\\)"):
        performances(np.zeros((10, 16, 2)), ref, 10.0, 40.0)
    with pytest.raises(InvalidInput, match="fps and reference_fps must be > 0"):
        performances(np.zeros((10, 17, 2)), ref, 0.0, 40.0)


def test_an_excursion_under_way_when_the_video_starts_is_not_whole():
    depth = _squats([(30, 50)], 70)
    depth[:12] = np.linspace(1.0, 0.0, 12)  # already squatting at the first frame
    reps = excursions(_squat_frames(depth), STAND, 10.0)
    assert [(r.start, r.end) for r in reps] == [pytest.approx((32, 48), abs=2)]


def test_performances_far_slower_than_the_reference_are_another_motion():
    ref_fps, fps = 40.0, 10.0
    slow = _squats([(10, 90), (110, 190)], 200)  # 8 s squats against the reference's 2 s
    assert performances(_squat_frames(slow), _reference_squat(ref_fps), fps, ref_fps).found == ()
