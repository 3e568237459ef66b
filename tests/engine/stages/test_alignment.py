"""Stage 2 DP (thesis 4.5.2, eq. 4.11): exact optimum, monotone, ends pinned."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.errors import InvalidInput
from engine.stages.alignment import band_mask, dp_path, rotation_samples, step_costs, window_size


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


def brute_force_steps(cost, window, g, min_step):
    n_v, n_r = cost.shape
    best = np.inf
    for mid in itertools.product(range(n_r), repeat=n_v - 2):
        path = (0, *mid, n_r - 1)
        steps = np.diff(path)
        if np.any(steps < min_step) or np.any(steps > window):
            continue
        best = min(best, cost[np.arange(n_v), path].sum() + g[steps].sum())
    return best


@settings(max_examples=40, deadline=None)
@given(
    n_v=st.integers(3, 4),
    n_r=st.integers(4, 7),
    window=st.integers(1, 4),
    seed=st.integers(0, 10_000),
    min_step=st.sampled_from([0, 1]),
)
def test_dp_with_step_cost_equals_brute_force(n_v, n_r, window, seed, min_step):
    rng = np.random.default_rng(seed)
    cost = rng.random((n_v, n_r))
    g = step_costs(window, (n_r - 1) / (n_v - 1), 0.3)
    best = brute_force_steps(cost, window, g, min_step)
    if not np.isfinite(best):
        return
    C, total = dp_path(cost, window=window, min_step=min_step, step_cost=g)
    assert total == pytest.approx(best)
    assert np.all(np.diff(C) >= min_step) and np.all(np.diff(C) <= window)


def test_step_cost_prefers_the_mean_slope():
    g = step_costs(8, 3.0, 1.0)
    assert np.argmin(g) == 3 and g[0] > g[6] > g[3] == 0.0
    # a flat cost: the step cost alone decides, so the path is the straight line
    C, _ = dp_path(np.zeros((5, 13)), window=8, min_step=0, step_cost=g)
    assert C.tolist() == [0, 3, 6, 9, 12]
    with pytest.raises(InvalidInput, match="step_cost must be"):
        dp_path(np.zeros((2, 3)), window=2, step_cost=np.zeros(2))


def _rendered_warp():
    """A synthetic reference (121 frames) and 31 silhouettes of it, 160x120, warped in time."""
    from engine.body.kinematics import forward_kinematics, rotation_about_axis
    from engine.body.shapes import BodyShape
    from engine.body.skeleton import PART_INDEX
    from engine.render import capsules
    from engine.render.camera import Camera

    shape = BodyShape.default(1.75)
    n_r = 121
    ph = np.linspace(0, 2.5 * np.pi, n_r)
    rots = np.broadcast_to(np.eye(3), (n_r, 12, 3, 3)).copy()
    # swing the arms and one leg: parts 7.. are limbs (upper arms about z, a leg about x)
    for name, axis, amp in (("l_upper_arm", [0, 0, 1], 1.2), ("r_upper_arm", [0, 0, 1], -1.0),
                            ("l_upper_leg", [1, 0, 0], 0.6)):  # fmt: skip
        rots[:, PART_INDEX[name]] = rotation_about_axis(np.array(axis, float), amp * np.sin(ph))
    ref = np.stack([forward_kinematics(shape.offsets, np.array([0, 1.0, 0]), r) for r in rots])
    cam = Camera(scale=60.0, theta_z=0.0, cx=80, cy=110, width=160, height=120)
    true_c = np.round(np.linspace(0, 1, 31) ** 1.3 * (n_r - 1)).astype(int)
    return ref, shape, cam, capsules.silhouettes(ref[true_c], shape, cam), true_c


def test_align_recovers_a_rendered_warp():
    from engine.stages.alignment import AlignmentSettings, align

    ref, shape, cam, sil, true_c = _rendered_warp()
    res = align(ref, shape, cam, sil)
    assert res.C[0] == 0 and res.C[-1] == len(ref) - 1
    assert np.all(np.diff(res.C) >= 0)
    assert np.mean(np.abs(res.C - true_c)) < 2.0
    # the default comparison height (240) is capped at the image's 120 rows
    same = align(ref, shape, cam, sil, settings=AlignmentSettings(compare_height=120))
    assert np.array_equal(res.cost, same.cost)


def test_threads_share_the_frames_without_changing_the_result():
    from engine.stages.alignment import AlignmentSettings, align

    ref, shape, cam, sil, _ = _rendered_warp()
    one = align(ref, shape, cam, sil, settings=AlignmentSettings(threads=1))
    two = align(ref, shape, cam, sil, settings=AlignmentSettings(threads=2))
    assert np.array_equal(one.cost, two.cost) and np.array_equal(one.sample, two.sample)
    assert np.array_equal(one.C, two.C)


def test_skin_contours_join_the_edges_only_when_asked():
    from engine.stages.alignment import AlignmentSettings, align

    ref, shape, cam, sil, _ = _rendered_warp()
    skin = np.zeros_like(sil)
    skin[:, 40:60, 70:90] = sil[:, 40:60, 70:90]  # a "face" inside the body
    plain = align(ref, shape, cam, sil).cost
    assert np.array_equal(align(ref, shape, cam, sil, skin).cost, plain)
    with_skin = align(ref, shape, cam, sil, skin, AlignmentSettings(skin_edges=True)).cost
    assert not np.array_equal(with_skin, plain)


from tests.conftest import BENCH_CASES  # noqa: E402

P1 = BENCH_CASES / "P1_warp_64_29"


@pytest.mark.skipif(not P1.exists(), reason="public cases not beside the clone")
def test_run_stages_0_2_on_a_short_clip():
    from engine.io.bvh import load_reference
    from engine.io.video import read_video
    from engine.pipeline import Stages02, run_stages_0_2
    from engine.stages.alignment import align

    ref = load_reference(P1 / "reference.bvh")
    video = read_video(P1 / "video.mp4", max_frames=40)
    st = run_stages_0_2(ref, video)
    assert isinstance(st, Stages02)
    assert st.alignment.C.shape == (40,) and st.alignment.C[0] == ref.motion.first_motion_frame
    assert np.all(np.diff(st.alignment.C) >= 0)
    assert set(st.width_factors) == {"torso", "head", "arms", "legs"}
    assert st.shape.radii.shape == ref.shape.radii.shape
    assert set(st.timing_s) == {"foreground", "calibration", "alignment"}
    # AlignmentSettings.realign: the correspondence is stage 2 run with the final camera and
    # the fitted body, not the first pass's calibration-frame camera and reference body
    c0 = ref.motion.first_motion_frame
    fg = st.foreground
    again = align(ref.motion.joints, st.shape, st.camera, fg.silhouettes, fg.skin, start=c0)
    assert np.array_equal(st.alignment.cost, again.cost)
    assert np.array_equal(st.alignment.C, again.C)
    unfitted = align(ref.motion.joints, ref.shape, st.camera, fg.silhouettes, fg.skin, start=c0)
    assert not np.array_equal(unfitted.cost, again.cost)  # the check above can tell
    seen = []
    run_stages_0_2(ref, video, on_progress=lambda stage, f: seen.append((stage, f)))
    steps = [f for stage, f in seen if stage == "alignment"]
    assert steps[-1] == pytest.approx(1.0) and np.all(np.diff(steps) >= -1e-12)


@pytest.mark.skipif(not P1.exists(), reason="public cases not beside the clone")
def test_coach_align_writes_a_file_the_scorer_reads(tmp_path):
    import json
    import subprocess
    import sys

    from engine.cli import main

    out = tmp_path / "align.json"
    rc = main(["align", str(P1 / "reference.bvh"), str(P1 / "video.mp4"), "--out", str(out),
               "--max-frames", "40"])  # fmt: skip
    assert rc == 0
    data = json.loads(out.read_text())
    assert len(data["frames"]) == 40 and "camera" in data
    score = P1.parents[1] / "score.py"
    r = subprocess.run([sys.executable, str(score), str(P1), str(out)], capture_output=True,
                       text=True, check=True)  # fmt: skip
    last = json.loads(r.stdout.strip().splitlines()[-1])
    assert last["frames_scored"] == 40 and np.isfinite(last["temporal_err_video_frames"])
