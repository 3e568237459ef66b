"""Stage 0 (thesis 4.1): silhouettes of public case P1 against the truth body."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from engine.errors import InvalidInput
from engine.render import capsules
from engine.render.camera import Camera
from engine.stages.foreground import ForegroundSettings, extract_foreground
from tests.conftest import BENCH_CASES, CMU

P1 = BENCH_CASES / "P1_warp_64_29"
P3 = BENCH_CASES / "P3_warp_64_17_grey"


def test_synthetic_blob_on_static_background(rng):
    bg = rng.integers(0, 255, (60, 80, 3), dtype=np.uint8)
    frames = np.repeat(bg[None], 12, 0)
    for i in range(12):
        frames[i, 20:45, 10 + 4 * i : 22 + 4 * i] = (20, 60, 200)
    fg = extract_foreground(frames)
    truth = np.zeros((60, 80), bool)
    truth[20:45, 10 + 4 * 5 : 22 + 4 * 5] = True
    iou = (fg.silhouettes[5] & truth).sum() / (fg.silhouettes[5] | truth).sum()
    assert iou > 0.8
    assert "no_person" not in fg.flags[5]


def test_interior_edges_add_the_outline_of_an_arm_over_the_torso(rng):
    # a blue "torso" crossed by a lighter "arm": the body region is the torso; only the
    # option adds the arm's outline inside it, and the region itself does not change
    bg = rng.integers(0, 255, (60, 80, 3), dtype=np.uint8)
    frames = np.repeat(bg[None], 12, 0)
    for i in range(12):
        frames[i, 10:50, 10 + 4 * i : 30 + 4 * i] = (20, 60, 200)
        frames[i, 26:32, 10 + 4 * i : 30 + 4 * i] = (120, 200, 120)  # not skin-coloured
    plain = extract_foreground(frames)
    rich = extract_foreground(frames, ForegroundSettings(interior_edges=True))
    assert (plain.silhouettes == rich.silhouettes).all()
    assert (rich.edges >= plain.edges).all()
    added = rich.edges[5] & ~plain.edges[5]
    rows = np.flatnonzero(added.any(1))
    assert added.sum() >= 20
    assert rows.min() >= 24 and rows.max() <= 33  # along the arm's top and bottom edges
    assert not (added & ~plain.silhouettes[5]).any()


def test_hole_showing_background_stays_open():
    from engine.stages.foreground.regions import _fill_holes

    body = np.zeros((200, 200), bool)  # the gap is 0.3 % of the image
    body[5:35, 5:25] = True
    body[12:30, 12:18] = False  # a gap closed all round (legs joined by the feet)
    sure_bg = np.zeros_like(body)
    sure_bg[20, 15] = True
    assert not _fill_holes(body, sure_bg)[20, 15]
    assert _fill_holes(body, np.zeros_like(body))[20, 15]


def test_validation():
    with pytest.raises(InvalidInput, match="frames must be uint8"):
        extract_foreground(np.zeros((1, 4, 4, 3), np.uint8))


def _against_truth_body(case, n_frames: int, learned: bool) -> tuple[float, float]:
    """Mean precision and recall of stage 0's regions against the truth's capsule body.

    The generator's mesh is wider than our capsules (clothes, shoes): precision is the share
    of the region within the capsule render dilated by 4 px, recall the share of the
    (undilated) capsule body the region covers, every 8th frame.
    """
    from engine.io.bvh import load_reference
    from engine.io.video import read_video
    from engine.stages.perception import perceive

    truth = json.loads((case / "truth.json").read_text())
    cam = Camera.from_dict(truth["camera"])
    shape = load_reference(case / "reference.bvh").shape
    v = read_video(case / "video.mp4", max_frames=n_frames)
    mask = perceive(v.frames).mask if learned else None
    fg = extract_foreground(v.frames, learned=mask)
    prec, rec = [], []
    for f in truth["frames"][:n_frames:8]:
        m = capsules.silhouettes(np.array(f["joints_3d"])[None], shape, cam)[0]
        big = cv2.dilate(m.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
        s = fg.silhouettes[f["t"]]
        prec.append((s & big).sum() / s.sum())
        rec.append((s & m).sum() / m.sum())
    return float(np.mean(prec)), float(np.mean(rec))


@pytest.mark.skipif(not P1.exists(), reason="public cases not beside the clone")
def test_public_case_p1_matches_truth_body():
    """Issue 20: the learned mask fused with the thesis' evidence finds the whole body.

    The thesis' region alone missed the dark shoes, which hardly move and print into the
    background (precision 0.98, recall 0.81 on these frames): the strict xfail this test was.
    """
    prec, rec = _against_truth_body(P1, 40, learned=True)
    assert prec >= 0.9 and rec >= 0.9, (prec, rec)


@pytest.mark.skipif(not P3.exists(), reason="public cases not beside the clone")
def test_grey_clothes_on_a_grey_wall_keep_their_legs():
    """P3: a squat in light grey against a grey wall he never leaves. The background model
    holds the legs, and the thesis' region loses them (recall 0.35 over the video,
    ``benchmarks/perception.py``); fused with the learned mask it keeps them. The whole
    video: the pose model finds him only once he moves, then tracks him back to the start."""
    thesis = _against_truth_body(P3, 127, learned=False)
    fused = _against_truth_body(P3, 127, learned=True)
    assert thesis[1] < 0.6  # what the issue reported: the legs are lost
    assert fused[0] >= 0.9 and fused[1] >= 0.9, fused


@pytest.mark.skipif(not (CMU / "64_29.bvh").exists(), reason="CMU data not beside the clone")
def test_synthetic_case_matches_rendered_truth():
    """Issue 3: silhouettes of a synthetic performer against the body it was rendered from.

    320 x 240 (the size the default settings are tuned for) at 12.5 fps: 59 frames, ~8 s.
    Measured on seeds 0-3: mean IoU 0.968-0.970, per-frame min 0.947-0.948 (seeds 0-2) and 0.88
    (seed 3, a leg lost against the floor in one frame); at 160 x 120 the mean drops to 0.93.
    """
    from engine.io.bvh import load_reference
    from engine.synth import SynthSettings, synthesize

    case = synthesize(
        load_reference(CMU / "64_29.bvh"),
        settings=SynthSettings(fps=12.5, width=320, height=240, noise_sigma=2.0),
        rng=np.random.default_rng(0),
    )
    fg = extract_foreground(case.frames)
    s, truth = fg.silhouettes, case.masks
    iou = (s & truth).sum((1, 2)) / np.maximum((s | truth).sum((1, 2)), 1)
    assert iou.mean() >= 0.9, np.round(iou, 3)
    assert iou.min() >= 0.85, np.round(iou, 3)
    assert not any("no_person" in f for f in fg.flags)


def test_silhouettes_do_not_depend_on_what_ran_before():
    # GrabCut seeds k-means from OpenCV's global RNG; a worker that segmented other videos
    # before must still get the same silhouettes (P2's first frames need GrabCut)
    from engine.io.video import read_video

    frames = read_video(BENCH_CASES / "P2_take_64_30_vs_64_29" / "video.mp4", max_frames=40).frames
    first = extract_foreground(frames).silhouettes
    cv2.setRNGSeed(12345)
    cv2.kmeans(np.random.default_rng(0).random((50, 3), np.float32), 3, None,
               (cv2.TERM_CRITERIA_MAX_ITER, 5, 0), 2, cv2.KMEANS_RANDOM_CENTERS)  # fmt: skip
    np.testing.assert_array_equal(extract_foreground(frames).silhouettes, first)


def test_threads_share_the_frames_without_changing_the_result():
    # P2's first frames need GrabCut, whose RNG is per thread and reset before each call
    from engine.io.video import read_video
    from engine.stages.perception import MediaPipePose, perceive

    frames = read_video(BENCH_CASES / "P2_take_64_30_vs_64_29" / "video.mp4", max_frames=24).frames
    mask = perceive(frames, MediaPipePose()).mask
    one = extract_foreground(frames, ForegroundSettings(threads=1), learned=mask)
    two = extract_foreground(frames, ForegroundSettings(threads=2), learned=mask)
    for a, b in [(one.silhouettes, two.silhouettes), (one.edges, two.edges), (one.skin, two.skin)]:
        np.testing.assert_array_equal(a, b)
    assert one.flags == two.flags


def test_fragment_near_the_body_is_kept_only_over_seen_background():
    # a lower leg cut off by a thin band the difference missed (trousers crossing the line
    # where wall meets floor) belongs to the body; a fragment far away, or one that is only a
    # guess over never-seen background, does not
    from engine.stages.foreground.regions import _clean

    mask = np.zeros((200, 100), bool)  # near = 4 % of 200 rows = 8 px
    mask[10:110, 20:40] = True  # the body
    mask[116:150, 24:30] = True  # the lower leg, 6 px below (wider than the closing bridges)
    mask[10:20, 80:86] = True  # a fragment far away
    kept, blobs = _clean(mask, 0.15, trusted=np.ones_like(mask))
    assert kept[130, 27] and not kept[15, 83] and blobs == 1
    guessed, _ = _clean(mask, 0.15, trusted=np.zeros_like(mask))
    assert not guessed[130, 27] and guessed[50, 30]
    plain, _ = _clean(mask, 0.15)
    assert not plain[130, 27]


@pytest.mark.skipif(not (CMU / "64_24.bvh").exists(), reason="CMU data not beside the clone")
def test_dark_legs_over_a_dark_floor_stay_in_the_calibration_frame(tmp_path):
    """Synthetic 64_24 (seed 2, as ``coach synth``): dark trousers over a dark floor, h264.

    Before the body pixels that differ from a seen background were trusted, GrabCut's colour
    models dropped both lower legs in frame 0 (IoU 0.81) and stage 1's camera came out 21.6 %
    small, cy 38 px off, at azimuth 30 deg. Measured now: IoU 0.94, scale +0.3 %, cy -0.1 px.
    ~25 s (rendering and encoding 139 frames).
    """
    from engine.io.bvh import load_reference
    from engine.io.case import write_case
    from engine.io.video import read_video
    from engine.stages.calibration import calibrate
    from engine.synth import SynthSettings, synthesize

    ref = load_reference(CMU / "64_24.bvh")
    case = synthesize(ref, settings=SynthSettings(max_frames=160), rng=np.random.default_rng(2))
    # through the video codec, as a user's upload: the raw renders do not show the failure
    video = write_case(case, tmp_path / "case", CMU / "64_24.bvh")["video"]
    fg = extract_foreground(read_video(video).frames)
    s, truth = fg.silhouettes[0], case.masks[0]
    assert (s & truth).sum() / (s | truth).sum() >= 0.9
    j = ref.motion.joints[ref.motion.first_motion_frame]
    cam, _ = calibrate(j, ref.shape, s, fg.edges[0])
    assert cam.scale == pytest.approx(case.camera.scale, rel=0.03)
    assert abs(cam.cy - case.camera.cy) < 5
    assert abs(np.degrees(cam.azimuth)) < 1e-6
