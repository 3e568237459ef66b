"""Stage 4 (thesis 4.7) on synthetic sequences whose truth is known by construction."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.errors import InvalidInput
from engine.stages.selection import (
    SelectionSettings,
    owned_frames,
    refine_segment,
    select_and_refine,
    smooth_errors,
)
from engine.types import Segments

REF_SEGMENTS = Segments((0, 40, 80), 120, ("up", "forward", "down"))
WAYPOINTS = np.array([[-0.2, -1.0, 0.3], [-1.0, 0.0, 0.2], [-0.3, 0.2, 1.0], [-0.2, -1.0, -0.3]])
WAYPOINTS /= np.linalg.norm(WAYPOINTS, axis=1, keepdims=True)


def _slerp(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> np.ndarray:
    om = np.arccos(np.clip(a @ b, -1, 1))
    return (np.sin((1 - u) * om)[:, None] * a + np.sin(u * om)[:, None] * b) / np.sin(om)


def _arm_direction(ref_frame: np.ndarray) -> np.ndarray:
    """Right-arm direction at (fractional) reference frames: great-circle arcs, corners at
    the reference boundaries so the wrists change direction there by about 90 deg."""
    f = np.asarray(ref_frame, float)
    seg = np.clip((f // 40).astype(int), 0, 2)
    u = (f - 40 * seg) / 40
    out = np.empty((f.size, 3))
    for s in range(3):
        m = seg == s
        out[m] = _slerp(WAYPOINTS[s], WAYPOINTS[s + 1], u[m])
    return out


def _body(d_r: np.ndarray, leg_deg: np.ndarray) -> np.ndarray:
    """Postures (n, 17, 3) from the right-arm direction (left mirrored) and a left-leg
    abduction error in degrees."""
    n = d_r.shape[0]
    base = np.array([
        [0, 1, 0], [0.1, 1, 0], [0.1, 0.55, 0], [0.1, 0.1, 0], [-0.1, 1, 0], [-0.1, 0.55, 0],
        [-0.1, 0.1, 0], [0, 1.2, 0], [0, 1.4, 0], [0.18, 1.45, 0], [0, 0, 0], [0, 0, 0],
        [-0.18, 1.45, 0], [0, 0, 0], [0, 0, 0], [0, 1.55, 0], [0, 1.75, 0],
    ], float)  # fmt: skip
    j = np.repeat(base[None], n, 0)
    d_l = d_r * np.array([-1, 1, 1])
    j[:, 13], j[:, 14] = j[:, 12] + 0.28 * d_r, j[:, 12] + 0.53 * d_r
    j[:, 10], j[:, 11] = j[:, 9] + 0.28 * d_l, j[:, 9] + 0.53 * d_l
    a = np.radians(leg_deg)
    c, s = np.cos(a), np.sin(a)
    for k in (2, 3):  # rotate the left leg about z at the left hip (abduction)
        v = base[k] - base[1]
        j[:, k, 0] = base[1, 0] + c * v[0] - s * v[1]
        j[:, k, 1] = base[1, 1] + s * v[0] + c * v[1]
    return j


def _flip_arm_depth(j: np.ndarray, shoulder: int) -> np.ndarray:
    out = j.copy()
    for k in (shoulder + 1, shoulder + 2):
        out[:, k, 2] = 2 * j[:, shoulder, 2] - j[:, k, 2]
    return out


def _candidates(truth: np.ndarray) -> list[np.ndarray]:
    """Per frame: the truth and its depth-flipped arms (same projection from the front), in
    a frame-dependent order so the index alone says nothing."""
    options = [truth, _flip_arm_depth(truth, 12), _flip_arm_depth(truth, 9),
               _flip_arm_depth(_flip_arm_depth(truth, 9), 12)]  # fmt: skip
    stack = np.stack(options, 1)  # (T', 4, 17, 3)
    rng = np.random.default_rng(7)
    return [stack[t, rng.permutation(4)] for t in range(truth.shape[0])]


def _performer(warp: np.ndarray, leg_deg: np.ndarray):
    truth = _body(_arm_direction(warp), leg_deg)
    ref = _body(_arm_direction(np.arange(121)), np.zeros(121))
    return truth, ref


def _warp_three_tempi() -> np.ndarray:
    """31 video frames: segment 1 fast (8 frames), 2 slow (14), 3 normal (8)."""
    return np.interp(np.arange(31), [0, 8, 22, 30], [0, 40, 80, 120])


def test_errors_only_in_segment_2_are_reported_there():
    warp = _warp_three_tempi()
    u = np.clip((warp - 40) / 40, 0, 1)
    leg = 40 * np.sin(np.pi * u)  # thesis table 2.1: correct, then wrong in segment 2
    truth, ref = _performer(warp, leg)
    C0 = np.linspace(0, 120, 31)  # stage 2's rough answer: uniform speed
    sel = select_and_refine(_candidates(truth), ref, REF_SEGMENTS, C0, fps_ratio=4.0)
    s1, s2, s3 = sel.segments
    assert [s.performer_start for s in sel.segments] == pytest.approx([0, 8, 22], abs=1)
    assert np.degrees(s1.mean_error) < 1.0 and np.degrees(s3.mean_error) < 1.0
    assert np.degrees(s2.mean_error) > 2.5
    assert np.degrees(s2.bone_mean_errors[[1, 2]]).min() > 15  # l_hip->l_knee, l_knee->l_ankle
    assert np.degrees(s1.bone_mean_errors).max() < 2
    # the truth is always selected: posture error equals the true error
    assert np.abs(sel.joints - truth).max() < 1e-9 or np.degrees(sel.posture_error).max() < 6
    assert np.abs(sel.C - warp).max() <= 4  # within one video frame's worth of reference
    assert all(s.status == "ok" for s in sel.segments)
    assert s1.tempo < 1.0 < s2.tempo
    assert sel.messages == ()


def test_identity_gives_diagonal_and_zero_error():
    warp = np.arange(0, 121, 4.0)
    truth, ref = _performer(warp, np.zeros(31))
    sel = select_and_refine(_candidates(truth), ref, REF_SEGMENTS, warp, fps_ratio=4.0)
    assert sel.performer_segments.starts == (0, 10, 20)
    np.testing.assert_array_equal(sel.C, warp.astype(int))
    assert np.degrees(sel.posture_error).max() < 1e-6


def test_pause_at_boundary_is_reduced_to_its_first_frame():
    # performer stops 6 frames at reference boundary 40 (thesis 2.1.3 item 4)
    warp = np.concatenate([np.linspace(0, 40, 11), np.full(6, 40.0), np.linspace(44, 120, 20)])
    truth, ref = _performer(warp, np.zeros(warp.size))
    C0 = np.linspace(0, 120, warp.size)
    # a uniform initial C is 3-4 frames off here: search a window as wide as the thesis' 8
    settings = SelectionSettings(boundary_window=8)
    sel = select_and_refine(
        _candidates(truth), ref, REF_SEGMENTS, C0, settings=settings, fps_ratio=4.0
    )
    assert abs(sel.performer_segments.starts[1] - 10) <= 1
    assert abs(sel.performer_segments.starts[2] - 26) <= 1
    assert np.degrees(sel.posture_error).mean() < 2


def test_missing_segment_is_flagged():
    # segment 2 skipped: video goes 0..40 then 80..120
    warp = np.concatenate([np.linspace(0, 40, 11), np.linspace(80, 120, 11)])
    truth, ref = _performer(warp, np.zeros(warp.size))
    sel = select_and_refine(_candidates(truth), ref, REF_SEGMENTS, warp, fps_ratio=4.0)
    assert [s.status for s in sel.segments] == ["ok", "missing", "ok"]
    assert any("missing" in m for m in sel.messages)
    s2 = sel.segments[1]
    assert all(
        "missing_segment" in sel.flags[t] for t in range(s2.performer_start, s2.performer_end + 1)
    )


def test_very_different_performer_gets_one_overall_message():
    warp = np.arange(0, 121, 4.0)
    truth, ref = _performer(warp, np.zeros(31))
    upside_down = truth * np.array([1, -1, -1])
    sel = select_and_refine(_candidates(upside_down), ref, REF_SEGMENTS, warp, fps_ratio=4.0)
    assert any("very different" in m for m in sel.messages)


def _brute_force(d_c: np.ndarray, window: int, min_step: int, band: float = np.inf) -> float:
    n_v, n_r, k = d_c.shape
    best = np.inf
    diag = np.linspace(0.0, n_r - 1, n_v)
    for steps in itertools.product(range(min_step, window + 1), repeat=n_v - 1):
        C = np.concatenate([[0], np.cumsum(steps)])
        if C[-1] != n_r - 1 or np.any(np.abs(C[1:] - diag[1:]) > band):
            continue
        for ell in itertools.product(range(k), repeat=n_v):
            e = d_c[np.arange(n_v), C, list(ell)]
            best = min(best, e.sum() + (np.diff(e) ** 2).sum())
    return best


@settings(max_examples=25, deadline=None)
@given(
    n_v=st.integers(2, 4), n_r=st.integers(2, 7), k=st.integers(1, 3),
    window=st.integers(1, 4), min_step=st.integers(0, 1), seed=st.integers(0, 10_000),
)  # fmt: skip
def test_dp_equals_brute_force(n_v, n_r, k, window, min_step, seed):
    d_c = np.random.default_rng(seed).uniform(0, 1, (n_v, n_r, k))
    C, ell, cost = refine_segment(d_c, window=window, band=n_r, min_step=min_step)
    expected = _brute_force(d_c, window, min_step)
    if not np.isfinite(expected):
        assert not np.isfinite(cost)
        return
    assert cost == pytest.approx(expected)
    # the traced path is valid and has that cost
    assert C[0] == 0 and C[-1] == n_r - 1
    assert np.all(np.diff(C) >= min_step) and np.all(np.diff(C) <= window)
    e = d_c[np.arange(n_v), C, ell]
    assert e.sum() + (np.diff(e) ** 2).sum() == pytest.approx(cost)


@settings(max_examples=25, deadline=None)
@given(
    n_v=st.integers(2, 5), n_r=st.integers(2, 9), k=st.integers(1, 3), window=st.integers(1, 4),
    band=st.integers(1, 4), min_step=st.integers(0, 1), seed=st.integers(0, 10_000),
    absent=st.floats(0.0, 0.3),
)  # fmt: skip
def test_dp_in_a_band_with_absent_candidates_equals_brute_force(
    n_v, n_r, k, window, band, min_step, seed, absent
):
    rng = np.random.default_rng(seed)
    d_c = rng.uniform(0, 1, (n_v, n_r, k))
    d_c[rng.uniform(size=d_c.shape) < absent] = np.inf
    C, ell, cost = refine_segment(d_c, window=window, band=band, min_step=min_step)
    expected = _brute_force(d_c, window, min_step, band)
    if not np.isfinite(expected):
        assert not np.isfinite(cost)
        return
    assert cost == pytest.approx(expected)
    diag = np.linspace(0.0, n_r - 1, n_v)
    assert np.all(np.abs(C[1:] - diag[1:]) <= band)
    e = d_c[np.arange(n_v), C, ell]
    assert e.sum() + (np.diff(e) ** 2).sum() == pytest.approx(cost)


def test_validation_names_the_parameter():
    ref = np.zeros((121, 17, 3))
    cands = [np.zeros((2, 17, 3))] * 5
    with pytest.raises(InvalidInput, match="reference_joints"):
        select_and_refine(cands, ref[:, :16], REF_SEGMENTS, np.zeros(5))
    with pytest.raises(InvalidInput, match=r"candidates\[1\]"):
        select_and_refine([cands[0], np.zeros((2, 3))], ref, REF_SEGMENTS, np.zeros(2))
    with pytest.raises(InvalidInput, match="C_initial"):
        select_and_refine(cands, ref, REF_SEGMENTS, np.zeros(4))
    with pytest.raises(InvalidInput, match="reference_segments"):
        select_and_refine(cands, ref, Segments((0, 40), 200), np.zeros(5))
    with pytest.raises(InvalidInput, match="fps_ratio"):
        select_and_refine(cands, ref, REF_SEGMENTS, np.zeros(5), fps_ratio=0)
    with pytest.raises(InvalidInput, match="boundary_joints"):
        select_and_refine(
            cands,
            ref,
            REF_SEGMENTS,
            np.zeros(5),
            settings=SelectionSettings(boundary_joints=("x",)),
        )
    with pytest.raises(InvalidInput, match="video_fps"):
        select_and_refine(cands, ref, REF_SEGMENTS, np.zeros(5), video_fps=0)
    for bad in (-0.1, float("nan")):
        with pytest.raises(InvalidInput, match="error_smoothing_s"):
            select_and_refine(
                cands, ref, REF_SEGMENTS, np.zeros(5),
                settings=SelectionSettings(error_smoothing_s=bad),
            )  # fmt: skip
    for bad in (0, 2):
        with pytest.raises(InvalidInput, match="error_median_frames"):
            select_and_refine(
                cands, ref, REF_SEGMENTS, np.zeros(5),
                settings=SelectionSettings(error_median_frames=bad),
            )  # fmt: skip


def test_error_smoothing_calms_flicker_but_keeps_the_step_at_a_boundary():
    """Segment 1 (frames 0-19) is right, segment 2 (20-39) wrong by 0.3 rad with +-0.1 of
    frame-to-frame flicker: the flicker shrinks, nothing leaks across the boundary, and a
    constant error stays the same up to the segments' ends."""
    err = np.zeros((40, 16))
    err[20:] = 0.3 + 0.1 * (-1.0) ** np.arange(20)[:, None]
    spans = owned_frames([(0, 20), (20, 39)])
    assert spans == [(0, 19), (20, 39)]
    out = smooth_errors(err, spans, sigma_frames=1.5)
    assert np.all(out[:20] == 0.0)  # frame 20 belongs to segment 2
    assert np.abs(out[20:] - 0.3).max() < 0.03
    assert out[20:].mean() == pytest.approx(0.3, abs=0.01)
    flat = np.full((40, 16), 0.2)
    assert smooth_errors(flat, spans, 3.0) == pytest.approx(flat)
    assert smooth_errors(err, spans, 0.0) is err


def test_error_median_drops_a_lone_spike_the_gaussian_would_spread():
    err = np.zeros((30, 16))
    err[10] = 0.5  # one frame whose selected candidate jumped alone
    spans = [(0, 29)]
    spread = smooth_errors(err, spans, sigma_frames=1.5)
    assert spread[8:13, 0].min() > 0.03  # the spike, spread over its neighbours
    assert np.all(smooth_errors(err, spans, sigma_frames=1.5, median_frames=3) == 0.0)
    # a real deviation lasting a few frames survives the median
    err[10:14] = 0.5
    kept = smooth_errors(err, spans, sigma_frames=1.5, median_frames=3)
    assert kept[11:13, 0].min() > 0.35


def _reference_and_truth(leg_peak_deg: float = 30.0):
    """Per frame two candidates, the reference posture at the true C and the truth, with
    d_S saying the truth explains the image better (0.00 vs 0.06)."""
    warp = np.arange(0, 121, 4.0)
    u = np.clip((warp - 40) / 40, 0, 1)
    truth, ref = _performer(warp, leg_peak_deg * np.sin(np.pi * u))
    at_c = _body(_arm_direction(warp), np.zeros(warp.size))
    cands = [np.stack([at_c[t], truth[t]]) for t in range(warp.size)]
    d_s = [np.array([0.06, 0.0])] * warp.size
    return warp, truth, ref, cands, d_s


def test_image_evidence_detects_errors_the_reference_candidate_would_hide():
    warp, truth, ref, cands, d_s = _reference_and_truth()
    thesis = select_and_refine(cands, ref, REF_SEGMENTS, warp, fps_ratio=4.0)
    # eq. 4.25 alone: the reference posture is a candidate with d_c = 0, so it always wins
    assert np.degrees(thesis.posture_error).max() < 1e-6
    sel = select_and_refine(cands, ref, REF_SEGMENTS, warp, fps_ratio=4.0, candidate_d_s=d_s)
    np.testing.assert_allclose(sel.joints, truth, atol=1e-9)
    assert np.degrees(sel.segments[1].bone_mean_errors[[1, 2]]).min() > 15
    assert np.degrees(sel.segments[0].mean_error) < 1e-6
    np.testing.assert_array_equal(sel.C, warp.astype(int))


def test_image_weight_zero_is_the_thesis_and_margin_drops_candidates():
    warp, truth, ref, cands, d_s = _reference_and_truth()
    off = SelectionSettings(image_weight=0.0)
    sel = select_and_refine(
        cands, ref, REF_SEGMENTS, warp, fps_ratio=4.0, candidate_d_s=d_s, settings=off
    )
    assert np.degrees(sel.posture_error).max() < 1e-6
    tight = SelectionSettings(image_weight=0.0, image_margin=0.01)
    sel = select_and_refine(
        cands, ref, REF_SEGMENTS, warp, fps_ratio=4.0, candidate_d_s=d_s, settings=tight
    )
    assert np.all(sel.selected == 1)  # the reference candidate is beyond the margin


def test_candidate_d_s_is_validated():
    warp, _, ref, cands, d_s = _reference_and_truth()
    with pytest.raises(InvalidInput, match="candidate_d_s: expected 31 frames"):
        select_and_refine(cands, ref, REF_SEGMENTS, warp, candidate_d_s=d_s[:3])
    with pytest.raises(InvalidInput, match=r"candidate_d_s\[0\]"):
        select_and_refine(cands, ref, REF_SEGMENTS, warp, candidate_d_s=[np.zeros(3)] * 31)
