"""How far to trust the reported postures: fit to the video, uncertainty, misfit flags.

Run by selection's step (:func:`engine.pipeline.select`) on the result document after the
thesis' stage 4 (4.7) has chosen one candidate per frame; all of it is beyond the thesis:

    flag_image_misfit   frames whose selected posture the video does not confirm
    add_image_best      in those frames, the candidate that explains the video best
    add_uncertainty     each bone error's range over the candidates the video cannot tell apart
    assess_fit          ``poor_fit`` when the reported motion does not explain the video
    note_repetitions    which of several whole performances the result covers
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from engine.render.camera import Camera
from engine.stage_outputs import Prepared
from engine.stages.selection import SelectionSettings
from engine.types import Selection


def add_uncertainty(
    doc: dict,
    candidates: Sequence[np.ndarray],
    d_s: Sequence[np.ndarray],
    reference: np.ndarray,
    margin: float,
) -> None:
    """How sure each bone's error is: its range over the candidates the video cannot tell
    from the reported one (beyond the thesis).

    A candidate whose image evidence (d_S + keypoints, the candidates' ``d_s``) is within
    ``margin`` of the best one's explains the video as well: one camera cannot choose
    between them. Its depth flips (thesis 4.6.5) project to the same image, so a bone bent
    in depth gets a wide range and an in-plane one a narrow range.

    Adds to every frame ``bone_error_range_deg`` ([lo, hi] per bone, the reported error
    always inside) and to every segment ``bone_uncertainty_deg`` (mean width per bone over
    the frames it owns).

    Parameters
    ----------
    doc : dict
        The result document, changed in place.
    candidates : list of ndarray, shape (K_t', 17, 3) each
    d_s : list of ndarray, shape (K_t',) each
    reference : ndarray, shape (T', 17, 3)
        The reference posture at C(t') of each frame.
    margin : float
    """
    from engine.measures import bone_angles

    widths = []
    for f, cands, d, ref in zip(doc["frames"], candidates, d_s, reference, strict=True):
        near = d <= d.min() + margin
        ang = np.degrees(bone_angles(cands[near], ref[None]))  # (K, 16)
        own = np.asarray(f["bone_errors_deg"], float)
        lo, hi = np.minimum(ang.min(0), own), np.maximum(ang.max(0), own)
        f["bone_error_range_deg"] = np.round(np.stack([lo, hi], -1), 2).tolist()
        widths.append(hi - lo)
    w = np.array(widths)
    t0 = doc["frames"][0]["t"] if doc["frames"] else 0
    for seg in doc["segments"]:
        a, b = seg["performer_start"] - t0, seg["performer_end"] - t0
        part = w[max(a, 0) : max(b, a + 1)]
        seg["bone_uncertainty_deg"] = np.round(part.mean(0), 2).tolist() if len(part) else []


def assess_fit(
    doc: dict, postures: np.ndarray, prepared: Prepared, settings: SelectionSettings
) -> None:
    """How well the reported postures explain the video; ``poor_fit`` when they do not.

    Two checks, each with its own plain message (beyond the thesis):

    1. **The body region.** Per frame, 1 - Dice overlap (d_A, thesis eq. 4.1) of the
       reported posture's capsule body with stage 0's region. Where the region is the
       performer this stays near 0.1-0.25 (the capsules are not clothes); where stage 0 could
       not separate him from the background it is a blob of wall that no posture explains.
       Poor when the median exceeds ``settings.poor_fit_region``.
    2. **The keypoints.** Per frame, the worst confident keypoint's distance to the reported
       joint (the better left/right reading, the detector's offsets removed), as a fraction
       of the body's height. On the six public cases under 0.3 in 0-3 % of the frames;
       where the video holds several repetitions of a one-repetition reference, or another
       motion, the reported postures leave the body (the real squat clips: 25 % and 38 %).
       Poor when more than ``settings.poor_fit_frames`` of the frames exceed
       ``settings.poor_fit_joint``.

    Parameters
    ----------
    doc : dict
        The result document, changed in place: ``summary.fit`` and, if poor, the status
        and a first message.
    postures : ndarray, shape (T', 17, 3)
        The reported (selected) postures.
    prepared : Prepared
    settings : SelectionSettings
    """
    from engine.render.capsules import Target, d_A_batch

    d_a = np.array([
        d_A_batch(p[None], Target.from_masks(sil, edg), prepared.shape, prepared.camera)[0]
        for p, sil, edg in zip(postures, prepared.silhouettes, prepared.edges, strict=True)
    ])  # fmt: skip
    far = _worst_keypoint(postures, prepared)
    summary = doc["summary"]
    summary["fit"] = {
        "region_mismatch_median": round(float(np.median(d_a)), 4),
        "region_mismatch_per_frame": np.round(d_a, 4).tolist(),
        "poor_frames": int(np.count_nonzero(d_a > settings.poor_fit_region)),
    }  # fmt: skip
    message = None
    if np.median(d_a) > settings.poor_fit_region:
        share = 100 * float(np.mean(d_a > settings.poor_fit_region))
        message = (
            "We could not separate you from the background well enough to measure your "
            f"posture (the body found in the video matches no posture in {share:.0f} % "
            "of the frames). Film in front of a plain wall, in clothes that differ from it, "
            "with the whole body in view and the camera still."
        )
    if far is not None:
        off = np.nan_to_num(far, nan=0.0) > settings.poor_fit_joint
        # JSON has no NaN: a frame without a confident keypoint says null
        summary["fit"]["keypoint_worst_per_frame"] = [
            round(float(x), 3) if np.isfinite(x) else None for x in far
        ]
        summary["fit"]["keypoint_off_frames"] = int(off.sum())
        if message is None and off.mean() > settings.poor_fit_frames:
            reps = _repetitions(prepared)
            message = _apart_message(float(off.mean()), reps, cut=bool(prepared.repetitions))
            if reps:
                summary["repetitions"] = reps
    if message is not None:
        summary["status"] = "poor_fit"
        summary["messages"] = [message, *summary["messages"]]


def note_repetitions(doc: dict, repetitions: Sequence[dict]) -> None:
    """Say which of several whole performances the result covers (beyond the thesis).

    ``repetitions`` are :attr:`Prepared.repetitions` (file frames, seconds, ``analysed``);
    they go to ``summary.repetitions`` and a message names them, so the performer knows
    the rest of the video was left out on purpose and which frames the numbers are about.
    """
    if not repetitions:
        return
    summary = doc["summary"]
    summary["repetitions"] = [dict(r) for r in repetitions]
    spans = ", ".join(f"{_clock(r['start_s'])}-{_clock(r['end_s'])}" for r in repetitions)
    chosen = next((r for r in repetitions if r.get("analysed")), repetitions[0])
    summary["messages"] = [
        f"The video holds {len(repetitions)} whole repetitions of the reference's motion "
        f"({spans}). This analysis covers the first one, {_clock(chosen['start_s'])}-"
        f"{_clock(chosen['end_s'])}; the rest of the video is not analysed.",
        *summary["messages"],
    ]


def note_framing(doc: dict, problems: Sequence[str]) -> None:
    """Add what the video's first frame says about the filming (:attr:`Prepared.framing`)
    to the result's messages: the upload page says it before an upload where the browser can
    decode the video; the result says it for every video."""
    if problems:
        doc["summary"]["messages"] = [
            *doc["summary"]["messages"],
            *(p if "first frame" in p else f"At the start of the video, {p[0].lower()}{p[1:]}"
              for p in problems),
        ]


def _repetitions(prepared: Prepared) -> list[dict]:
    """The repetitions of the reference's motion the keypoints show, when more than one
    (:func:`engine.stages.repetitions.excursions`): video frames and seconds; none when the
    analysis already covers one of several (:func:`note_repetitions` names them)."""
    from engine.stages.repetitions import excursions

    if prepared.keypoints is None or prepared.repetitions:
        return []
    start = prepared.camera.project(prepared.reference_joints[prepared.first_motion_frame][None])
    fps = prepared.video.fps
    reps = excursions(prepared.keypoints, start[0], fps)
    if len(reps) < 2:
        return []
    return [
        {"start": r.start, "end": r.end,
         "start_s": round(r.start / fps, 2), "end_s": round(r.end / fps, 2)}
        for r in reps
    ]  # fmt: skip


def _apart_message(share: float, repetitions: list[dict], *, cut: bool = False) -> str:
    """What to do when the reported motion leaves the body in ``share`` of the frames
    (``cut``: of the one repetition analysed out of several)."""
    said = f"Your body and the expert's motion part ways in {100 * share:.0f} % of the frames"
    if cut:
        return (
            f"{said} of the repetition analysed: your motion differs from the reference's "
            "more than the fit can follow (another motion, or a much shallower or deeper "
            "one), so read the numbers with care."
        )
    if repetitions:
        spans = ", ".join(f"{_clock(r['start_s'])}-{_clock(r['end_s'])}" for r in repetitions)
        return (
            f"{said}: the video holds {len(repetitions)} whole repetitions ({spans}) and the "
            "reference one. Trim the video to one of them and upload it again."
        )
    return (
        f"{said}: the video may hold several repetitions, or another motion than the "
        "reference. Trim it to one repetition of the reference's motion, from its first "
        "posture to its last."
    )


def _clock(seconds: float) -> str:
    """``m:ss.s`` as a video player shows it."""
    minutes, rest = divmod(seconds, 60.0)
    return f"{int(minutes)}:{rest:04.1f}"


def _worst_keypoint(postures: np.ndarray, prepared: Prepared) -> np.ndarray | None:
    """Per frame, the largest distance from a confident keypoint (> 0.5) to its reported
    joint as a fraction of the body's height in the image, over the better of the two
    readings, (T',); NaN without confident keypoints; None without perception."""
    readings = prepared.frame_keypoints(range(prepared.n_frames))
    if readings is None:
        return None
    kp, conf = readings  # (T', 2, 17, 2), (T', 2, 17)
    ok = (conf > 0.5) & np.isfinite(kp).all(-1)
    d = np.linalg.norm(prepared.camera.project(postures)[:, None] - np.nan_to_num(kp), axis=-1)
    mean = (d * ok).sum(-1) / np.maximum(ok.sum(-1), 1)
    best = np.argmin(np.where(ok.any(-1), mean, np.inf), axis=1)  # (T',)
    rows = np.arange(len(postures))
    worst = np.where(ok[rows, best], d[rows, best], -np.inf).max(-1)
    height_px = prepared.camera.scale * float(
        np.ptp(prepared.reference_joints[prepared.first_motion_frame][:, 1])
    )
    return np.where(np.isfinite(worst), worst / max(height_px, 1e-9), np.nan)


def add_image_best(
    doc: dict, candidates: Sequence[np.ndarray], d_s: Sequence[np.ndarray], camera: Camera
) -> None:
    """In ``image_misfit`` frames, the candidate that explains the video best (beyond the thesis).

    Adds ``image_best`` (its index in ``candidates``) and ``image_best_joints_2d`` (its
    projection, video pixels) to those frames of the result ``doc``, so a coach can see what
    the video suggests where it disagrees with the reported posture (a lifted foot the prior
    keeps down). Its depth is as uncertain as any single-view posture's.

    Parameters
    ----------
    doc : dict
        The result document (DESIGN.md), changed in place.
    candidates : list of ndarray, shape (K_t', 17, 3) each
    d_s : list of ndarray, shape (K_t',) each
    camera : Camera
        In the video file's pixels (the result's ``joints_2d``).
    """
    for f, cands, d in zip(doc["frames"], candidates, d_s, strict=True):
        if "image_misfit" not in f["flags"]:
            continue
        k = int(np.argmin(d))
        f["image_best"] = k
        f["image_best_joints_2d"] = np.round(camera.project(cands[k]), 2).tolist()


def flag_image_misfit(
    selection: Selection, d_s: Sequence[np.ndarray], margin: float
) -> Selection:
    """Flag frames whose selected posture the video does not confirm (beyond the thesis).

    The calibration frame (video frame 0, whose posture is the reference's by the thesis'
    assumption B'_0 = B_0) sets the d_S a correct posture reaches on this video; a frame
    whose selected candidate scores worse by more than ``margin`` gets ``image_misfit``,
    and a summary message says how many, so a coach never reads a small error there as
    certain.

    Parameters
    ----------
    selection : Selection
    d_s : list of ndarray, shape (K_t',) each
        d_S of every candidate, indices matching ``selection.selected``.
    margin : float
    """
    chosen = np.array([d[int(k)] for d, k in zip(d_s, selection.selected, strict=True)])
    bad = chosen > chosen[0] + margin
    if not bad.any():
        return selection
    flags = tuple(
        (*f, "image_misfit") if b else tuple(f)
        for f, b in zip(selection.flags, bad, strict=True)
    )
    n, total = int(bad.sum()), len(bad)
    message = (
        f"The video matches the reported posture poorly in {n} of {total} frames (shaded "
        "on the error plot): the errors shown there may be underestimated, so look at those "
        "frames yourself."
    )
    return dataclasses.replace(selection, flags=flags, messages=(*selection.messages, message))
