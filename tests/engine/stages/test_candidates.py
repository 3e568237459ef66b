"""Stage 3 (thesis 4.6): candidates by nonparametric BP on small synthetic frames."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from engine.body.kinematics import forward_kinematics, rotation_about_axis
from engine.body.shapes import BodyShape
from engine.body.skeleton import PART_INDEX
from engine.errors import InvalidInput
from engine.measures import d_B
from engine.render.camera import Camera
from engine.render.capsules import render
from engine.stages.candidates import (
    CandidateSettings,
    FrameCandidates,
    estimate_candidates,
    estimate_candidates_chunk,
    limits_ok,
    perturb_parts,
)

SMALL = CandidateSettings(
    n_samples=24, n_iterations=8, refine_sweeps=3, n_candidates=12, estimator="bp"
)
SHAPE = BodyShape.default(1.75)


def _posture(forearm_deg: float) -> np.ndarray:
    R = np.broadcast_to(np.eye(3), (12, 3, 3)).copy()
    # arms a little down, left forearm turned in depth by forearm_deg
    R[PART_INDEX["l_upper_arm"]] = rotation_about_axis(np.array([0, 0, 1.0]), -0.3)
    R[PART_INDEX["r_upper_arm"]] = rotation_about_axis(np.array([0, 0, 1.0]), 0.3)
    R[PART_INDEX["l_lower_arm"]] = (
        rotation_about_axis(np.array([0, 1.0, 0]), np.radians(forearm_deg))
        @ R[PART_INDEX["l_upper_arm"]]
    )
    R[PART_INDEX["r_lower_arm"]] = R[PART_INDEX["r_upper_arm"]]
    return forward_kinematics(SHAPE.offsets, np.array([0.0, 1.0, 0.0]), R)


def _camera(joints: np.ndarray) -> Camera:
    cam = Camera(scale=100.0 / 1.75, width=160, height=120)
    c = cam.project(joints).mean(0)
    return cam.with_(cx=80.0 - c[0], cy=60.0 - c[1])


@pytest.fixture(scope="module")
def flipped() -> tuple[np.ndarray, np.ndarray, Camera, FrameCandidates]:
    truth = _posture(-50.0)  # forearm towards the camera
    init = _posture(50.0)  # same projection, away from the camera
    cam = _camera(truth)
    r = render(truth, SHAPE, cam)
    sil, edges = r.silhouette, r.edges
    fc = estimate_candidates(
        sil, edges, cam, SHAPE, init, settings=SMALL, rng=np.random.default_rng(3)
    )
    return truth, init, cam, fc


def test_flipped_forearm_is_among_candidates(flipped) -> None:
    truth, init, cam, fc = flipped
    assert np.degrees(d_B(init, truth)) > 5.0
    assert np.degrees(d_B(fc.candidates, truth).min()) < 5.0
    # the flips keep the projection; only the appended initial posture may differ
    err = np.linalg.norm(cam.project(fc.candidates) - cam.project(fc.candidates[0]), axis=-1)
    assert (err.max(axis=1) < 1e-6).sum() >= len(fc.candidates) - 1
    assert d_B(fc.candidates, init).min() <= 1e-6


def test_hybrid_has_in_plane_estimate_first_and_bp_candidates(flipped) -> None:
    truth, init, cam, _ = flipped
    r = render(truth, SHAPE, cam)
    hybrid = replace(SMALL, estimator="hybrid")
    fc = estimate_candidates(
        r.silhouette, r.edges, cam, SHAPE, init, settings=hybrid, rng=np.random.default_rng(3)
    )
    in_plane = estimate_candidates(
        r.silhouette, r.edges, cam, SHAPE, init, settings=replace(SMALL, estimator="in_plane"),
        rng=np.random.default_rng(3),
    )  # fmt: skip
    assert len(fc.candidates) <= hybrid.n_candidates
    np.testing.assert_allclose(fc.candidates[0], in_plane.candidates[0])
    # the depth flip is found by BP's half of the set
    assert np.degrees(d_B(fc.candidates, truth).min()) < 5.0
    assert limits_ok(fc.candidates).all()


def test_candidates_respect_joint_limits(flipped) -> None:
    assert limits_ok(flipped[3].candidates).all()
    assert flipped[3].candidates.shape[1:] == (17, 3)
    assert flipped[3].d_s.shape == (len(flipped[3].candidates),)


def test_schedule_converges(flipped) -> None:
    h = flipped[3].history
    assert h.shape == (SMALL.n_iterations + 1,)
    assert h[-1] <= h[0] + 0.005  # starts on the true projection here
    assert np.all(np.diff(h[-4:]) <= 0.02)


def test_chunk_reports_progress(rng) -> None:
    truth = _posture(-30.0)
    cam = _camera(truth)
    r = render(truth, SHAPE, cam)
    sil, edges = r.silhouette, r.edges
    seen = []
    s = CandidateSettings(n_samples=8, n_iterations=2, refine_sweeps=0, n_candidates=4)
    out = estimate_candidates_chunk(
        np.stack([sil, sil]), np.stack([edges, edges]), cam, SHAPE, np.stack([truth, truth]),
        settings=s, rng=rng, on_progress=lambda st, f: seen.append((st, f)),
    )  # fmt: skip
    assert len(out) == 2 and seen[-1] == ("candidates", 1.0)


def test_bad_inputs_raise(rng) -> None:
    truth = _posture(0.0)
    cam = _camera(truth)
    r = render(truth, SHAPE, cam)
    sil, edges = r.silhouette, r.edges
    with pytest.raises(InvalidInput, match="target_silhouette"):
        estimate_candidates(sil[:10], edges, cam, SHAPE, truth, rng=rng)
    with pytest.raises(InvalidInput, match="target_edges"):
        estimate_candidates(sil, edges[:10], cam, SHAPE, truth, rng=rng)
    with pytest.raises(InvalidInput, match="empty"):
        estimate_candidates(np.zeros_like(sil), edges, cam, SHAPE, truth, rng=rng)
    with pytest.raises(InvalidInput, match="initial_joints"):
        estimate_candidates(sil, edges, cam, SHAPE, truth[:5], rng=rng)
    with pytest.raises(InvalidInput, match="NaN"):
        estimate_candidates(sil, edges, cam, SHAPE, truth * np.nan, rng=rng)
    with pytest.raises(InvalidInput, match="camera"):
        estimate_candidates(sil, edges, None, SHAPE, truth, rng=rng)  # type: ignore[arg-type]
    with pytest.raises(InvalidInput, match="n_samples"):
        estimate_candidates(
            sil, edges, cam, SHAPE, truth, settings=CandidateSettings(n_samples=1), rng=rng
        )


def test_best_candidate_never_worse_than_initial() -> None:
    # a body wider than the model (the video's clothed body): fitting the silhouette better by
    # bending the parts must not lose the initial posture, which is the truth here
    truth = _posture(30.0)
    cam = _camera(truth)
    wide = BodyShape(SHAPE.offsets, SHAPE.radii * 1.3)
    r = render(truth, wide, cam)
    s = CandidateSettings(n_samples=12, n_iterations=3, refine_sweeps=1, n_candidates=6)
    fc = estimate_candidates(
        r.silhouette, r.edges, cam, SHAPE, truth, settings=s, rng=np.random.default_rng(0)
    )
    assert d_B(fc.candidates, truth).min() <= 1e-6
    assert limits_ok(fc.candidates).all()


def test_bp_prior_keeps_the_estimate_near_the_reference_under_model_mismatch() -> None:
    # a wider body than the model: without the prior BP bends the parts to fill the region
    truth = _posture(30.0)
    cam = _camera(truth)
    r = render(truth, BodyShape(SHAPE.offsets, SHAPE.radii * 1.4), cam)
    err = {}
    for mu in (0.0, 2.0):
        s = CandidateSettings(
            n_samples=16,
            n_iterations=4,
            refine_sweeps=4,
            n_candidates=4,
            bp_prior_weight=mu,
            estimator="bp",
        )
        fc = estimate_candidates(
            r.silhouette, r.edges, cam, SHAPE, truth, settings=s, rng=np.random.default_rng(0)
        )
        err[mu] = float(d_B(fc.candidates[0], truth))
    assert err[2.0] < err[0.0]


def test_estimator_must_be_known():
    with pytest.raises(InvalidInput, match="estimator"):
        CandidateSettings(estimator="nope").validate()


@pytest.mark.parametrize(
    "bad",
    [{"escape_dirs": -1}, {"restart_ds": -0.01}, {"occluded_tolerance": -0.1},
     {"occluded_tolerance": float("nan")}, {"restarts": -1}, {"restart_ds": float("nan")},
     {"restart_deg": -1.0}, {"subpixel_rows": -1}, {"escape_prefilter": -1},
     {"alternatives": -1}, {"alternative_share": 0.0}, {"alternative_share": 1.5},
     {"alternative_min_deg": float("nan")}],
)  # fmt: skip
def test_escape_and_occlusion_settings_are_checked(bad: dict) -> None:
    with pytest.raises(InvalidInput, match=next(iter(bad))):
        CandidateSettings(**bad).validate()
    CandidateSettings.exact_body().validate()


def test_in_plane_keeps_the_root_unless_allowed_to_move_it() -> None:
    truth = _posture(0.0)
    cam = _camera(truth)
    shifted = truth + np.array([3.0, 0.0, 0.0]) / cam.scale  # the body 3 px to the right
    r = render(shifted, SHAPE, cam)
    s = replace(SMALL, estimator="in_plane", in_plane_prior=0.0)
    kept = estimate_candidates(
        r.silhouette, r.edges, cam, SHAPE, truth, settings=s, rng=np.random.default_rng(0)
    )
    np.testing.assert_allclose(kept.candidates[0][0], truth[0])
    moved = estimate_candidates(
        r.silhouette, r.edges, cam, SHAPE, truth,
        settings=replace(s, in_plane_move_root=True), rng=np.random.default_rng(0),
    )  # fmt: skip
    shift_px = (cam.project(moved.candidates[0]) - cam.project(truth))[0, 0]
    assert 1.5 < shift_px < 4.5, shift_px


def test_chunk_needs_one_generator_or_one_per_frame() -> None:
    from engine.stages.candidates import estimate_candidates_chunk

    truth = _posture(0.0)
    cam = _camera(truth)
    r = render(truth, SHAPE, cam)
    sils, edges = np.stack([r.silhouette] * 2), np.stack([r.edges] * 2)
    init = np.stack([truth] * 2)
    with pytest.raises(InvalidInput, match="one per frame"):
        estimate_candidates_chunk(
            sils, edges, cam, SHAPE, init, settings=SMALL, rng=[np.random.default_rng(0)]
        )
    out = estimate_candidates_chunk(
        sils, edges, cam, SHAPE, init, settings=SMALL,
        rng=[np.random.default_rng(0), np.random.default_rng(1)],
    )  # fmt: skip
    assert len(out) == 2


def _arm_posture(l_upper: np.ndarray, l_lower: np.ndarray) -> np.ndarray:
    """The default body, right arm a little down, left arm bones along the given directions."""
    from engine.stages.candidates.postures import _turn_to

    def towards(d: list[float]) -> np.ndarray:
        d = np.asarray(d, float)
        return _turn_to(np.array([1.0, 0.0, 0.0]), (d / np.linalg.norm(d))[None])[0]

    R = np.broadcast_to(np.eye(3), (12, 3, 3)).copy()
    R[PART_INDEX["r_upper_arm"]] = R[PART_INDEX["r_lower_arm"]] = rotation_about_axis(
        np.array([0, 0, 1.0]), 0.3
    )
    R[PART_INDEX["l_upper_arm"]] = towards(l_upper)
    R[PART_INDEX["l_lower_arm"]] = towards(l_lower)
    return forward_kinematics(SHAPE.offsets, np.array([0.0, 1.0, 0.0]), R)


def test_escape_brings_back_an_arm_started_on_the_other_side() -> None:
    # the left arm is raised; the start has it hanging down, 120 deg away: BP and the
    # pattern search are local and stay near the start, the escape's jumps do not
    truth = _arm_posture([1.0, 1.2, 0.2], [1.0, 1.6, -0.3])
    init = _arm_posture([1.0, -1.7, 0.2], [1.0, -1.7, 0.2])
    cam = _camera(truth)
    r = render(truth, SHAPE, cam)
    err = {}
    for dirs, prefilter in ((0, 0), (48, 0), (48, 8)):
        s = replace(SMALL, escape_dirs=dirs, refine_alone=dirs > 0, lambda_e=1.0, prior_weight=0.0,
                    escape_prefilter=prefilter)  # fmt: skip
        fc = estimate_candidates(
            r.silhouette, r.edges, cam, SHAPE, init, settings=s, rng=np.random.default_rng(0)
        )
        best = fc.candidates[int(np.argmin(fc.d_s))]
        err[dirs, prefilter] = np.linalg.norm(cam.project(best) - cam.project(truth), axis=-1).max()
        assert limits_ok(fc.candidates).all()
    assert err[0, 0] > 10.0, err  # without the escape the wrist stays far off
    assert err[48, 0] < 3.0, err  # every joint within 3 px on a 100 px body
    assert err[48, 8] < 3.0, err  # also when only the 8 best jumps by d_A get a full d_S


def test_restarts_leave_a_wrong_basin_and_wait_for_a_poor_fit() -> None:
    # every part 25 deg off (thesis 5.2.2's start, harsher): this start's BP settles with a
    # wrist 11 px off and d_S 0.12; BP again from its estimate shaken finds the right basin
    truth = _posture(-30.0)
    cam = _camera(truth)
    r = render(truth, SHAPE, cam)
    init = perturb_parts(truth, 25.0, np.random.default_rng(4))
    base = replace(SMALL, lambda_e=1.0, prior_weight=0.0)
    runs = {}
    for name, extra in (("off", {}), ("on", {"restarts": 2}), ("fit", {"restarts": 2,
                        "restart_ds": 1.0})):  # fmt: skip
        fc = estimate_candidates(
            r.silhouette, r.edges, cam, SHAPE, init, settings=replace(base, **extra),
            rng=np.random.default_rng(0),
        )  # fmt: skip
        best = fc.candidates[int(np.argmin(fc.d_s))]
        err = np.linalg.norm(cam.project(best) - cam.project(truth), axis=-1).max()
        runs[name] = (fc, err)
        assert limits_ok(fc.candidates).all()
    assert runs["off"][1] > 5.0 and runs["on"][1] < 2.0, (runs["off"][1], runs["on"][1])
    assert runs["on"][0].d_s.min() < runs["off"][0].d_s.min()
    # a fit already under restart_ds is left alone (same candidates, same random stream)
    np.testing.assert_array_equal(runs["fit"][0].candidates, runs["off"][0].candidates)


def test_subpixel_rows_score_candidates_with_the_continuous_d_A(flipped) -> None:
    from engine.render.capsules import Target, d_A_batch

    truth, init, cam, _ = flipped
    r = render(truth, SHAPE, cam)
    s = replace(SMALL, subpixel_rows=4)  # lambda_e 0: d_S is d_A alone
    fc = estimate_candidates(
        r.silhouette, r.edges, cam, SHAPE, init, settings=s, rng=np.random.default_rng(3)
    )
    target = Target.from_masks(r.silhouette, r.edges)
    smooth = d_A_batch(fc.candidates, target, SHAPE, cam, subpixel_rows=4)
    np.testing.assert_allclose(fc.d_s, smooth, atol=1e-12)
    assert not np.allclose(fc.d_s, d_A_batch(fc.candidates, target, SHAPE, cam))


def test_occluded_part_takes_the_reference_pose_where_the_image_allows() -> None:
    from engine.render.capsules import Target
    from engine.stages.candidates.occlusion import _reset_occluded
    from engine.stages.candidates.postures import _frame_offsets
    from engine.stages.candidates.scorer import _Scorer

    # left forearm across the back, hidden by the chest
    truth = _arm_posture([-0.5, -1.0, -0.6], [-1.0, 0.0, -2.0])
    cam = _camera(truth)
    r = render(truth, SHAPE, cam)
    s = CandidateSettings.exact_body()
    assert s.occluded_tolerance < 0.05
    scorer = _Scorer(Target.from_masks(r.silhouette, r.edges), SHAPE, cam, truth, s)
    offsets = _frame_offsets(truth, SHAPE.offsets)
    hidden_too = _arm_posture([-0.5, -1.0, -0.6], [-1.0, 0.3, -2.0])
    sticks_out = _arm_posture([-0.5, -1.0, -0.6], [1.0, 0.2, 0.3])
    flags: list[str] = []
    reset = _reset_occluded(scorer, truth, hidden_too, offsets, s, flags)
    assert flags == ["occluded:l_wrist"]
    np.testing.assert_allclose(reset[11] - reset[10], hidden_too[11] - hidden_too[10], atol=1e-9)
    flags = []
    kept = _reset_occluded(scorer, truth, sticks_out, offsets, s, flags)
    assert flags == ["occluded:l_wrist"]  # still flagged: the image does not show it
    np.testing.assert_allclose(kept, truth)  # but the image rules out the reference's pose
    # the defaults (for clothed bodies, whose d_S is no judge of a hidden part) always reset
    forced = _reset_occluded(scorer, truth, sticks_out, offsets, CandidateSettings(), [])
    np.testing.assert_allclose(forced[11] - forced[10], sticks_out[11] - sticks_out[10], atol=1e-9)


def test_a_lifted_foot_the_prior_keeps_down_is_flagged_as_misfit() -> None:
    """The demo's situation: a shin bent back in depth lifts the foot in the picture.

    BP finds it, the in-plane estimate (what selection reports while the prior wins) keeps
    the foot on the floor, and the default misfit margin flags the frame.
    """
    from engine.stages.assessment import flag_image_misfit
    from engine.stages.selection import Selection, SelectionSettings
    from engine.types import Segments

    ref = _posture(0.0)
    R = np.broadcast_to(np.eye(3), (12, 3, 3)).copy()
    R[PART_INDEX["l_upper_arm"]] = R[PART_INDEX["l_lower_arm"]] = rotation_about_axis(
        np.array([0, 0, 1.0]), -0.3
    )
    R[PART_INDEX["r_upper_arm"]] = R[PART_INDEX["r_lower_arm"]] = rotation_about_axis(
        np.array([0, 0, 1.0]), 0.3
    )
    R[PART_INDEX["r_lower_leg"]] = rotation_about_axis(np.array([1.0, 0, 0]), np.radians(90))
    lifted = forward_kinematics(SHAPE.offsets, ref[0], R)
    cam = _camera(ref)
    ankle = 6  # r_ankle
    assert np.linalg.norm(cam.project(lifted)[ankle] - cam.project(ref)[ankle]) > 10
    s = CandidateSettings(n_candidates=12)  # the defaults' hybrid estimator
    fcs = []
    for truth in (ref, lifted):
        r = render(truth, SHAPE, cam)
        fcs.append(
            estimate_candidates(
                r.silhouette, r.edges, cam, SHAPE, ref, settings=s, rng=np.random.default_rng(1)
            )
        )
    uv = cam.project(fcs[1].candidates)[:, ankle]
    err = np.linalg.norm(uv - cam.project(lifted)[ankle], axis=-1)
    assert err[0] > 10 and err.min() < 3, err
    n = 2
    sel = Selection(
        performer_segments=Segments((0,), n - 1), C=np.zeros(n, int), selected=np.zeros(n, int),
        joints=np.stack([f.candidates[0] for f in fcs]), posture_error=np.zeros(n),
        bone_errors=np.zeros((n, 16)), flags=((),) * n, segments=(), messages=(),
    )  # fmt: skip
    out = flag_image_misfit(sel, [f.d_s for f in fcs], SelectionSettings().misfit_margin)
    assert [("image_misfit" in f) for f in out.flags] == [False, True]


def test_alternative_local_optima_join_the_candidates() -> None:
    from engine.stages.candidates import generate_candidates
    from engine.stages.candidates.alternatives import _alternatives, _with_alternatives

    truth = _posture(-30.0)
    cam = _camera(truth)
    rng = np.random.default_rng(5)
    near = perturb_parts(truth, 1.0, rng)  # under alternative_min_deg from the best
    far1, far2 = perturb_parts(truth, 25.0, rng), perturb_parts(truth, 25.0, rng)
    found = [(0.01, truth), (0.02, near), (0.03, far1), (0.05, far2)]
    s = replace(SMALL, alternatives=1, alternative_min_deg=3.0)
    alts = _alternatives(found, s)
    assert len(alts) == 1 and alts[0] is far1  # the nearest optimum is a copy, not an alternative
    assert len(_alternatives(found, replace(s, alternatives=2))) == 2
    assert _alternatives(found, replace(s, alternatives=0)) == []
    assert _alternatives(found[:1], s) == []

    s = replace(s, alternatives=2, alternative_share=0.5)
    main = generate_candidates(truth, [truth], cam, s)
    cands = _with_alternatives(main, [far1, far2], [truth], cam, s)
    assert len(cands) <= s.n_candidates
    k = min(len(main), 6)  # half the set stays the best's
    np.testing.assert_array_equal(cands[:k], main[:k])
    for a in (far1, far2):  # each alternative itself is a candidate
        assert np.min(np.abs(cands - a).max(axis=(1, 2))) < 1e-9


def test_refine_with_a_step_per_part_stops_converged_parts() -> None:
    from engine.render.capsules import Target
    from engine.stages.candidates.refinement import _refine
    from engine.stages.candidates.scorer import _Scorer

    truth = _posture(-30.0)
    cam = _camera(truth)
    r = render(truth, SHAPE, cam)
    start = perturb_parts(truth, 6.0, np.random.default_rng(2))
    out = {}
    for per_part in (False, True):
        s = replace(SMALL, refine_sweeps=24, refine_step0_deg=4.0, refine_per_part=per_part,
                    lambda_e=1.0)  # fmt: skip
        scorer = _Scorer(Target.from_masks(r.silhouette, r.edges), SHAPE, cam, start, s)
        q, d = _refine(scorer, start, cam, s)
        err = np.linalg.norm(cam.project(q) - cam.project(truth), axis=-1).mean()
        out[per_part] = (d, err, scorer.n_evals)
        assert d < float(scorer.full(start[None])[0])
        assert limits_ok(q)
    assert out[True][1] < 1.0, out  # mean joint error under a pixel on a 100 px body
    assert out[True][2] < out[False][2], out  # fewer postures scored


def _plain_pattern_search(scorer, joints, cam, s):  # noqa: ANN001, ANN202
    """Thesis 6.4's pattern search written out, every part tried in every sweep."""
    from engine.body.skeleton import N_PARTS
    from engine.stages.candidates.refinement import _pattern_moves

    cur, best = joints.copy(), float(scorer.full(joints[None])[0])
    step = np.radians(s.refine_step0_deg)
    for _ in range(s.refine_sweeps):
        improved = False
        for p in range(N_PARTS):
            batch = _pattern_moves(cur, p, step, cam, in_plane=False, alone=False, move_root=True)
            sc = scorer.full(batch)
            k = int(np.argmin(sc))
            if sc[k] < best - 1e-9 and limits_ok(batch[k]):
                cur, best, improved = batch[k], float(sc[k]), True
        if not improved:
            step /= 2.0
        if step < np.radians(s.refine_min_step_deg):
            break
    return cur, best


@pytest.mark.parametrize("lambda_e", [0.0, 1.0])
def test_refine_skips_only_the_moves_it_has_already_scored(lambda_e: float) -> None:
    """A part that found nothing is not tried again at the same step until another part
    moved: the result is the plain search's, for fewer scores."""
    from engine.render.capsules import Target
    from engine.stages.candidates.refinement import _refine
    from engine.stages.candidates.scorer import _Scorer

    truth = _posture(-30.0)
    cam = _camera(truth)
    r = render(truth, SHAPE, cam)
    start = perturb_parts(truth, 8.0, np.random.default_rng(5))
    s = replace(SMALL, refine_sweeps=14, refine_step0_deg=8.0, lambda_e=lambda_e)
    plain = _Scorer(Target.from_masks(r.silhouette, r.edges), SHAPE, cam, start, s)
    want = _plain_pattern_search(plain, start, cam, s)
    scorer = _Scorer(Target.from_masks(r.silhouette, r.edges), SHAPE, cam, start, s)
    got = _refine(scorer, start, cam, s)
    np.testing.assert_array_equal(got[0], want[0])
    assert got[1] == want[1]
    assert want[1] < float(plain.full(start[None])[0])  # the search did move
    assert scorer.n_evals < plain.n_evals, (scorer.n_evals, plain.n_evals)


@pytest.mark.parametrize("estimator", ["bp", "hybrid"])
def test_a_left_right_swapped_detection_gives_the_same_candidates(estimator):
    """Issue 20: the keypoint term reads the detection both ways, so a pose model that
    swaps left and right leaves stage 3's result exactly as it was."""
    from engine.stages.perception import MIRROR, readings

    truth = _posture(-30.0)
    init = _posture(10.0)
    cam = _camera(truth)
    r = render(truth, SHAPE, cam)
    rng = np.random.default_rng(5)
    kp = cam.project(truth) + rng.normal(0, 1.5, (17, 2))
    conf = rng.uniform(0.5, 1.0, 17)
    s = replace(SMALL, estimator=estimator, keypoint_weight=0.5)

    def run(points: np.ndarray, c: np.ndarray) -> FrameCandidates:
        return estimate_candidates(r.silhouette, r.edges, cam, SHAPE, init, settings=s,
                                   rng=np.random.default_rng(3),
                                   keypoints=readings(points, c))  # fmt: skip

    straight, swapped = run(kp, conf), run(kp[MIRROR], conf[MIRROR])
    np.testing.assert_array_equal(straight.candidates, swapped.candidates)
    np.testing.assert_array_equal(straight.d_s, swapped.d_s)
    # and the keypoints do count: without them the estimate differs
    plain = estimate_candidates(r.silhouette, r.edges, cam, SHAPE, init, settings=s,
                                rng=np.random.default_rng(3))  # fmt: skip
    assert not np.array_equal(plain.d_s, straight.d_s)
