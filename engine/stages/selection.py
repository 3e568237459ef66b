"""Stage 4: performer segment boundaries, candidate selection, refined C, posture errors.

Thesis 4.7 (4.7.1 boundaries, 4.7.2 per-segment DP, eq. 4.22-4.30), with the constraints of
2.1.6 (B temporal order, C boundary similarity, D small rate of change of errors) and three
additions from chapter 6:

- 6.6 missing or extraneous segments are *detected and reported* (a performer segment far too
  short is "missing", far too long is "extra_motion") instead of being forced to match;
- 6.7 a performer whose selected postures are far from the reference everywhere gets one
  overall message (``Selection.messages``) rather than a per-bone list of noise;
- 2.1.3 item 4: a performer who pauses at a boundary (a run of unchanged postures) has the
  pause reduced to its first frame, whose in/out motion directions are those around the pause.

Everything here works on joint positions in the world frame, shape (..., 17, 3); errors are in
radians (degrees only in :mod:`engine.io.result`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d, median_filter

from engine.body.kinematics import bone_directions
from engine.body.skeleton import JOINT_INDEX, N_JOINTS
from engine.errors import InvalidInput
from engine.types import SegmentReport, Segments, Selection

ProgressFn = Callable[[str, float], None]


@dataclass(frozen=True)
class SelectionSettings:
    """Tuning of stage 4; defaults are the thesis' values where it gives them.

    Attributes
    ----------
    window_k : float
        Window factor k of the per-segment DP, w = k L_i / L'_i (thesis 5.5.3: k = 10).
    band : float
        Normalised bandwidth beta_i / L_i around the segment diagonal (thesis 5.5.3: 25 %).
    boundary_window : int
        Half-width omega of the boundary search window, video frames (thesis 4.7.1 step 2).
        Stage 2's C is already close, and a wide window lets the velocity condition latch onto
        a neighbouring direction change. Mean boundary error (video frames), window 8 -> 2
        with BP candidates: P1 3.43 -> 1.93, P2 4.00 -> 2.00, a synthetic 25 fps case 0.77 ->
        0.27. With the hybrid stage 3, window 2 -> 1 (= 0 on all four): P1 1.93 -> 1.43, P1
        at 15 fps 2.22 -> 1.22, P2 1.50 -> 1.50, synthetic 0.47 -> 0.27.
    smooth_threshold_deg : float
        Largest d_B between consecutive candidates of a "smooth" sequence (4.7.1 step 3).
    boundary_joints : tuple of str
        Joints whose velocity direction change marks a boundary (5.4.2: the right wrist).
    direction_change_deg : float
        Minimum direction change at a boundary: tau = cos(this) (2.1.1 item 4; 60 deg Taichi,
        120 deg golf).
    pause_speed : float
        Joint speed (metres per video frame, relative to the hip) below which the performer is
        considered still (2.1.3 item 4).
    missing_tempo : float
        A segment whose tempo is below this fraction of the median tempo, or shorter than
        ``min_segment_frames``, is reported missing (6.6).
    extra_tempo : float
        A segment whose tempo is above this multiple of the median tempo is reported as
        containing extraneous motion (6.6).
    min_segment_frames : int
        Fewest video frames a performed segment spans (end - start).
    large_error_deg : float
        Mean posture error above which the performance is "very different" (6.7).
    image_weight : float
        mu of the image-evidence term of the candidate cost, radians of d_B per unit of d_S
        (beyond the thesis): d_c'(t', t, l) = d_B(B_t, B'_t'l) + mu (d_S(B'_t'l) - min_k
        d_S(B'_t'k)). The thesis' d_c (eq. 4.25) alone picks the candidate closest to the
        reference; when the initial posture (the reference itself) is among the candidates it
        always wins and no error is ever detected. The term makes a candidate pay for
        explaining the image worse than the best one. 0 gives the thesis' cost. Used only when
        ``candidate_d_s`` is given.
    image_margin : float
        Candidates whose d_S exceeds their frame's best by more than this are not
        image-consistent and are dropped from selection (never the frame's best). The
        default keeps every candidate: on the public cases the capsule body's lowest d_S
        lies 10-30 deg from the truth, 0.05-0.1 below the true posture's, so a tight margin
        drops the only right candidate.
    misfit_margin : float
        A frame whose selected posture explains the image worse (d_S) than the calibration
        frame's by more than this is flagged ``image_misfit``: the posture reported there is not
        confirmed by the video, and its errors may be underestimated (beyond the thesis).
        ``benchmarks/cases.py`` (true posture error of flagged / unflagged frames, deg): at
        0.03 the flagged frames are the worse ones on all seven cases (P1 4.7 / 3.0, P2 8.6 /
        5.7, the synthetic ones 4.4 / 3.2, 5.9 / 3.7, 12.5 / 7.9, 10.2 / 3.2, the demo's
        6.0 / 0.1), flagging 2-52 % of the frames; at 0.04 P1's six flagged frames are its
        better ones; at 0.1 only one case flags anything. Where the reported error is
        smallest, on the demo's lifted foot, the flag is what tells the coach to look.
    anchor_deg_per_frame : float
        Cost (degrees of d_B) per video frame that C(t') departs from stage 2's C, and
        likewise per video frame a performer boundary departs from stage 2's (4.7.1 step 4);
        beyond the thesis. The thesis' DP (eq. 4.24) lets C wander wherever the candidates
        fit a little better; with the capsule body's noisy candidates C got worse than stage
        2's: on P1 (stage 2 C error 1.51 video frames) 5.48 without the anchor, 1.78 with 1,
        1.61 with 3; with the true C as input 0.06 -> 0.55 without, 0.2 with 1. Larger
        values stop the DP from correcting a rough C with good candidates (the synthetic
        test with stage 2's uniform-speed C needs <= ~2). 0 gives the thesis' DP.
    error_smoothing_s, error_median_frames : float, int
        Each bone's error is smoothed over time within each performer segment: a running
        median of ``error_median_frames`` (odd; 1 disables it), then a Gaussian of std
        ``error_smoothing_s`` seconds (0 disables it). The thesis asks for a small rate of
        change of eps_t' within a segment (2.1.3 item 6, 2.1.6 D) through d_s in the DP
        (eq. 4.24); this also smooths the reported errors themselves. A performer's
        deviation persists for tenths of a second (the public cases' truth: lag-1
        autocorrelation of eps_t' 0.99), while the selected candidates flicker between
        neighbouring solutions (ours 0.91 on P1, 0.73 on P2), and now and then one frame's
        candidate jumps alone: the median drops such a spike, which the Gaussian alone would
        spread over its neighbours. Only the errors are smoothed; the selected postures are
        the frames' own. ``benchmarks/cases.py --extra --save DIR`` with both off, then
        ``benchmarks/smoothing.py DIR`` (rank correlation of eps_t' with the truth /
        bone-error estimation error in deg, mean of eleven cases): none 0.596 / 3.58;
        Gaussian 0.05 s alone 0.602 / 3.48 (``syn_64_29_13`` 0.32 -> 0.17: spikes spread);
        median 3 alone 0.608 / 3.52; median 3 then 0.05 s 0.622 / 3.47 (P1 0.61 -> 0.67, P2
        0.49 -> 0.52, ``syn_64_29_13`` 0.38); median 5 then 0.05 s 0.616 / 3.46; median 3
        then 0.1 s 0.622 / 3.45 (``syn_64_17_1`` 0.75 -> 0.69: errors that change fast
        within a short segment blur).
    uncertainty_margin : float
        Candidates whose image evidence is within this of the frame's best explain the video
        as well; the range of each bone's error over them is its uncertainty
        (:func:`engine.pipeline.add_uncertainty`).
    poor_fit_region : float
        When the median over frames of 1 - Dice between the reported posture's body and
        stage 0's region exceeds this, the result's status is ``poor_fit``
        (:func:`engine.pipeline.assess_fit`): the region is not the performer. Beyond the
        thesis.
    poor_fit_joint, poor_fit_frames : float
        When more than ``poor_fit_frames`` of the frames have a confident keypoint farther
        than ``poor_fit_joint`` of the body's height from its reported joint, the status is
        ``poor_fit`` too: the reported motion leaves the body (several repetitions, another
        motion). Measured (:func:`engine.pipeline.assess_fit`): 0-3 % of the frames on the
        six public cases, 13 % on the real golf clip, 25 % and 38 % on the real squat clips
        (several repetitions against one).
    """

    window_k: float = 10.0
    band: float = 0.25
    boundary_window: int = 1
    smooth_threshold_deg: float = 25.0
    boundary_joints: tuple[str, ...] = ("l_wrist", "r_wrist")
    direction_change_deg: float = 60.0
    pause_speed: float = 0.004
    missing_tempo: float = 0.25
    extra_tempo: float = 3.0
    min_segment_frames: int = 2
    large_error_deg: float = 40.0
    image_weight: float = 2.0
    image_margin: float = 1.0
    anchor_deg_per_frame: float = 1.0
    misfit_margin: float = 0.03
    error_smoothing_s: float = 0.05
    error_median_frames: int = 3
    poor_fit_region: float = 0.45
    poor_fit_joint: float = 0.3
    poor_fit_frames: float = 0.2
    uncertainty_margin: float = 0.01


# --------------------------------------------------------------------------- validation


def _validate(
    candidates: Sequence[np.ndarray],
    reference_joints: np.ndarray,
    reference_segments: Segments,
    C_initial: np.ndarray,
    fps_ratio: float,
) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    ref = np.asarray(reference_joints, dtype=float)
    if ref.ndim != 3 or ref.shape[1:] != (N_JOINTS, 3) or ref.shape[0] < 2:
        raise InvalidInput(f"reference_joints: expected shape (T>=2, 17, 3), got {ref.shape}")
    if len(candidates) < 2:
        raise InvalidInput(f"candidates: need at least 2 video frames, got {len(candidates)}")
    cands = []
    for i, c in enumerate(candidates):
        a = np.asarray(c, dtype=float)
        if a.ndim != 3 or a.shape[1:] != (N_JOINTS, 3) or a.shape[0] < 1:
            raise InvalidInput(f"candidates[{i}]: expected shape (K>=1, 17, 3), got {a.shape}")
        cands.append(a)
    C0 = np.asarray(C_initial, dtype=float)
    if C0.shape != (len(cands),):
        raise InvalidInput(f"C_initial: expected shape ({len(cands)},), got {C0.shape}")
    starts = reference_segments.starts
    if (
        not starts
        or list(starts) != sorted(set(starts))
        or starts[0] < 0
        or reference_segments.end <= starts[-1]
        or reference_segments.end >= ref.shape[0]
    ):
        raise InvalidInput(
            f"reference_segments: starts must increase within [0, {ref.shape[0] - 1}] and end "
            f"after the last start, got starts={starts} end={reference_segments.end}"
        )
    if not np.isfinite(fps_ratio) or fps_ratio <= 0:
        raise InvalidInput(f"fps_ratio: expected a positive number, got {fps_ratio}")
    return cands, ref, C0


def _check_settings(s: SelectionSettings, video_fps: float) -> None:
    """Refuse settings (and the video rate) stage 4 cannot work with, naming the parameter."""
    unknown = [j for j in s.boundary_joints if j not in JOINT_INDEX]
    if unknown:
        raise InvalidInput(f"settings.boundary_joints: unknown joints {unknown}")
    if not np.isfinite(video_fps) or video_fps <= 0:
        raise InvalidInput(f"video_fps: expected a positive number, got {video_fps}")
    if not s.error_smoothing_s >= 0:  # also refuses NaN
        raise InvalidInput(f"settings.error_smoothing_s must be >= 0, got {s.error_smoothing_s}")
    if s.error_median_frames < 1 or s.error_median_frames % 2 == 0:
        raise InvalidInput(
            f"settings.error_median_frames must be odd and >= 1, got {s.error_median_frames}"
        )


def _pad(candidates: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Candidates padded to (T', K_max, 17, 3) and a validity mask (T', K_max)."""
    k = max(c.shape[0] for c in candidates)
    out = np.zeros((len(candidates), k, N_JOINTS, 3))
    valid = np.zeros((len(candidates), k), dtype=bool)
    for i, c in enumerate(candidates):
        out[i, : c.shape[0]] = c
        out[i, c.shape[0] :] = c[0]
        valid[i, : c.shape[0]] = True
    return out, valid


def _image_cost(
    d_s: Sequence[np.ndarray] | None, valid: np.ndarray, s: SelectionSettings
) -> np.ndarray:
    """mu (d_S - min_k d_S) per padded candidate, inf beyond the margin, shape (T', K_max)."""
    out = np.zeros(valid.shape)
    if d_s is None:
        return out
    if len(d_s) != valid.shape[0]:
        raise InvalidInput(f"candidate_d_s: expected {valid.shape[0]} frames, got {len(d_s)}")
    for i, d in enumerate(d_s):
        d = np.asarray(d, float)
        k = int(valid[i].sum())
        if d.shape != (k,):
            raise InvalidInput(f"candidate_d_s[{i}]: expected shape ({k},), got {d.shape}")
        rel = d - d.min()
        out[i, :k] = np.where(rel <= s.image_margin, s.image_weight * rel, np.inf)
    return out


def _angles(dirs_a: np.ndarray, dirs_b: np.ndarray) -> np.ndarray:
    """Bone angles from unit bone directions (..., 16, 3) -> (..., 16), radians."""
    return np.arccos(np.clip(np.sum(dirs_a * dirs_b, -1), -1.0, 1.0))


@dataclass(frozen=True)
class _Evidence:
    """What stages 4.7.1 and 4.7.2 compare, prepared once per call.

    Attributes
    ----------
    cand_joints : ndarray, shape (T', K, 17, 3)
        Candidates padded to K = max K_t' (:func:`_pad`).
    cand_dirs : ndarray, shape (T', K, 16, 3)
        Their unit bone directions.
    valid : ndarray of bool, shape (T', K)
        Real candidates within ``image_margin`` of their frame's best.
    image : ndarray, shape (T', K)
        Image-evidence cost mu (d_S - min_k d_S) (:func:`_image_cost`); 0 without d_S.
    ref_dirs : ndarray, shape (T, 16, 3)
        Unit bone directions of the reference B_t.
    C0 : ndarray, shape (T',)
        Stage 2's correspondence (may be fractional).
    """

    cand_joints: np.ndarray
    cand_dirs: np.ndarray
    valid: np.ndarray
    image: np.ndarray
    ref_dirs: np.ndarray
    C0: np.ndarray

    @property
    def n_frames(self) -> int:
        """T'."""
        return int(self.C0.shape[0])


def _evidence(
    cands: list[np.ndarray],
    ref: np.ndarray,
    C0: np.ndarray,
    d_s: Sequence[np.ndarray] | None,
    s: SelectionSettings,
) -> _Evidence:
    """Pad the candidates (K_t', 17, 3) per frame and take bone directions of them and of
    the reference (T, 17, 3); candidates the image rules out become invalid."""
    cand_joints, valid = _pad(cands)
    image = _image_cost(d_s, valid, s)
    valid = valid & np.isfinite(image)
    return _Evidence(
        cand_joints, bone_directions(cand_joints), valid, image, bone_directions(ref), C0
    )


# --------------------------------------------------------------------------- 4.7.1


def _smooth_sequences(dirs: np.ndarray, valid: np.ndarray, threshold: float) -> np.ndarray:
    """Smooth candidate sequences over a window (thesis 4.7.1 step 3).

    Viterbi over the window with transition cost d_B between consecutive candidates; one
    sequence per candidate at the window's last frame, kept when every step stays below
    ``threshold``.

    Parameters
    ----------
    dirs : ndarray, shape (n, K, 16, 3)
        Bone directions of the window's candidates.
    valid : ndarray of bool, shape (n, K)
    threshold : float
        Radians.

    Returns
    -------
    sequences : ndarray of int, shape (M, n)
        Candidate index per window frame, M >= 1 (the smoothest is kept even above threshold).
    """
    n, k = valid.shape
    cost = np.where(valid[0], 0.0, np.inf)
    worst = np.zeros(k)
    back = np.zeros((n, k), dtype=int)
    for i in range(1, n):
        step = _angles(dirs[i - 1][:, None], dirs[i][None]).mean(-1)  # (K_prev, K)
        total = cost[:, None] + step
        back[i] = np.argmin(total, axis=0)
        cost = np.where(valid[i], total[back[i], np.arange(k)], np.inf)
        worst = np.maximum(worst[back[i]], step[back[i], np.arange(k)])
    paths = np.empty((k, n), dtype=int)
    paths[:, -1] = np.arange(k)
    for i in range(n - 1, 0, -1):
        paths[:, i - 1] = back[i, paths[:, i]]
    keep = np.isfinite(cost) & (worst <= threshold)
    if not keep.any():
        keep = cost == cost.min()
    return np.unique(paths[keep], axis=0)


def _boundary_frames(rel: np.ndarray, cos_tau: float, pause_speed: float) -> np.ndarray:
    """Frames of a sequence that satisfy the boundary condition (thesis 2.1.6 C).

    v_tau . v_tau+1 < tau for any boundary joint, with directions taken from the last moving
    velocity before and the first moving velocity after, so a pause (2.1.3 item 4) counts as a
    boundary at its first still frame.

    Parameters
    ----------
    rel : ndarray, shape (n, J_b, 3)
        Boundary joints relative to the hip along one smooth sequence.

    Returns
    -------
    frames : ndarray of int
        Window-relative indices tau in [1, n-2].
    """
    n = rel.shape[0]
    if n < 3:
        return np.zeros(0, dtype=int)
    v = np.diff(rel, axis=0)  # v[i] = motion from i to i+1, (n-1, J_b, 3)
    speed = np.linalg.norm(v, axis=-1)
    moving = speed > pause_speed
    unit = v / np.maximum(speed, 1e-12)[..., None]
    # last moving velocity arriving at tau (index <= tau-1), first leaving it (index >= tau)
    idx = np.arange(n - 1)[:, None].repeat(rel.shape[1], 1)
    last_in = np.maximum.accumulate(np.where(moving, idx, -1), axis=0)
    first_out = np.minimum.accumulate(np.where(moving, idx, n)[::-1], axis=0)[::-1]
    taus = np.arange(1, n - 1)
    li, fo = last_in[taus - 1], first_out[taus]
    ok = (li >= 0) & (fo < n - 1)
    j = np.arange(rel.shape[1])
    cos = np.sum(unit[np.clip(li, 0, n - 2), j] * unit[np.clip(fo, 0, n - 2), j], -1)
    hit = (ok & (cos < cos_tau)).any(-1)
    # a still run is one boundary: keep only the first frame of a run of hits that is still
    still_at = ~moving[taus].any(-1) & ~moving[taus - 1].any(-1)
    first_of_run = hit & ~(still_at & np.r_[False, hit[:-1]])
    return taus[first_of_run]


def _find_boundary(
    lo: int,
    hi: int,
    t_ref: int,
    ev: _Evidence,
    s: SelectionSettings,
    joint_ids: np.ndarray,
    initial: int,
) -> tuple[int, bool]:
    """Performer boundary for reference boundary ``t_ref`` in [lo, hi].

    Thesis 4.7.1 steps 3-5, eq. 4.23; returns (frame, whether the velocity condition held).
    """
    seqs = _smooth_sequences(
        ev.cand_dirs[lo : hi + 1], ev.valid[lo : hi + 1], np.radians(s.smooth_threshold_deg)
    )
    frames = np.arange(lo, hi + 1)
    best: tuple[float, int] | None = None
    fallback: tuple[float, int] | None = None
    for seq in seqs:
        joints = ev.cand_joints[frames, seq]
        rel = joints[:, joint_ids] - joints[:, :1]
        err = _angles(ev.ref_dirs[t_ref][None], ev.cand_dirs[frames, seq]).mean(-1)  # d_B
        # image evidence and the pull towards stage 2's boundary (see SelectionSettings)
        err = err + ev.image[frames, seq]
        err = err + np.radians(s.anchor_deg_per_frame) * np.abs(frames - initial)
        for tau in _boundary_frames(rel, np.cos(np.radians(s.direction_change_deg)), s.pause_speed):
            if best is None or err[tau] < best[0]:
                best = (float(err[tau]), int(lo + tau))
        i = int(np.argmin(err))
        if fallback is None or err[i] < fallback[0]:
            fallback = (float(err[i]), int(lo + i))
    if best is not None:
        return best[1], True
    assert fallback is not None  # seqs is never empty
    return fallback[1], False


def _initial_boundary(C0: np.ndarray, t_ref: int) -> int:
    """First video frame whose C reaches ``t_ref`` (4.7.1 step 1)."""
    hit = np.flatnonzero(C0 >= t_ref)
    return int(hit[0]) if hit.size else len(C0) - 1


@dataclass(frozen=True)
class _Segmentation:
    """The performer's segments (4.7.1) and their 6.6 status, one entry per reference segment.

    Attributes
    ----------
    bounds : list of (int, int)
        (start, end) reference frames of each segment, inclusive.
    starts : list of int
        First video frame of each segment (monotone; ``starts[0] == 0``).
    spans : list of (int, int)
        (start, end) video frames of each segment, inclusive; consecutive ones share a frame.
    initial : list of int
        Stage 2's start of each segment (:func:`_initial_boundary`), then the last frame.
    found : list of bool
        Whether each start satisfied the velocity condition (the first always does).
    tempo : ndarray, shape (n_segments,)
        Performer duration / reference duration.
    status : list of str
        "ok", "missing" or "extra_motion".
    names : tuple of str
        The reference segments' names ("" when unnamed).
    """

    bounds: list[tuple[int, int]]
    starts: list[int]
    spans: list[tuple[int, int]]
    initial: list[int]
    found: list[bool]
    tempo: np.ndarray
    status: list[str]
    names: tuple[str, ...]


def _segment_names(segments: Segments) -> tuple[str, ...]:
    """One name per segment: the given ones, padded (or cut) with ""."""
    n = len(segments.starts)
    names = tuple(segments.names) or ("",) * n
    if len(names) != n:
        names = tuple(names[i] if i < len(names) else "" for i in range(n))
    return names


def _performer_starts(
    ev: _Evidence,
    bounds: list[tuple[int, int]],
    s: SelectionSettings,
    on_progress: ProgressFn | None,
) -> tuple[list[int], list[int], list[bool]]:
    """Performer boundaries (thesis 4.7.1), one per interior reference boundary.

    Each is searched within ``s.boundary_window`` of stage 2's and never before the previous
    one, so the segments stay in temporal order (2.1.6 B). Returns (initial, starts, found):
    stage 2's starts plus the last frame, the chosen starts, and whether the velocity
    condition held at each.
    """
    n_v = ev.n_frames
    joint_ids = np.array([JOINT_INDEX[j] for j in s.boundary_joints])
    initial = [0] + [_initial_boundary(ev.C0, t) for t, _ in bounds[1:]] + [n_v - 1]
    starts = [0]
    found = [True]
    for j, (t_ref, _) in enumerate(bounds[1:], start=1):
        lo = max(starts[-1], initial[j] - s.boundary_window)
        hi = min(n_v - 1, initial[j] + s.boundary_window)
        lo = min(lo, hi)
        tau, ok = _find_boundary(lo, hi, t_ref, ev, s, joint_ids, initial[j])
        starts.append(max(tau, starts[-1]))
        found.append(ok)
        if on_progress:
            on_progress("selection", 0.2 * j / max(len(bounds) - 1, 1))
    return initial, starts, found


def _segment_status(
    spans: list[tuple[int, int]],
    bounds: list[tuple[int, int]],
    fps_ratio: float,
    s: SelectionSettings,
) -> tuple[np.ndarray, list[str]]:
    """Tempo (n_segments,) of each performed segment and its status (thesis 6.6).

    A segment far slower than the median tempo, or too short, is "missing"; one far faster
    is "extra_motion": reported rather than forced to match.
    """
    tempo = np.array(
        [
            (pe - ps) * fps_ratio / max(re - rs, 1)
            for (ps, pe), (rs, re) in zip(spans, bounds, strict=True)
        ]
    )
    median = float(np.median(tempo[tempo > 0])) if (tempo > 0).any() else 1.0
    status = []
    for i, (ps, pe) in enumerate(spans):
        if pe - ps < s.min_segment_frames or tempo[i] < s.missing_tempo * median:
            status.append("missing")
        elif tempo[i] > s.extra_tempo * median:
            status.append("extra_motion")
        else:
            status.append("ok")
    return tempo, status


def _segment_performer(
    ev: _Evidence,
    reference_segments: Segments,
    fps_ratio: float,
    s: SelectionSettings,
    on_progress: ProgressFn | None,
) -> _Segmentation:
    """Thesis 4.7.1 (performer boundaries) and 6.6 (missing or extra segments)."""
    bounds = reference_segments.bounds()
    initial, starts, found = _performer_starts(ev, bounds, s, on_progress)
    spans = list(zip(starts, starts[1:] + [ev.n_frames - 1], strict=True))
    tempo, status = _segment_status(spans, bounds, fps_ratio, s)
    names = _segment_names(reference_segments)
    return _Segmentation(bounds, starts, spans, initial, found, tempo, status, names)


# --------------------------------------------------------------------------- 4.7.2


def refine_segment(
    d_c: np.ndarray, *, window: int, band: int, min_step: int = 1
) -> tuple[np.ndarray, np.ndarray, float]:
    """Least-cost path over (t', t, l) in one segment (thesis 4.7.2, eq. 4.24-4.30).

    The path starts at (0, 0, l) and ends at (n'-1, n-1, l): C(t'_b) = t_b and C(t'_e) = t_e.
    The predecessor of (t', t, l) is (t'-1, t-i, k) with i in [min_step, window] (constraint B;
    the thesis' i = 1..w+1), and only t within ``band`` of the segment's diagonal is searched.
    Cost per step d_c(t', t, l) + (d_c(t', t, l) - d_c(t'-1, s, k))^2 (eq. 4.25, 4.26).
    Complexity O(w beta L'_B N_B^2).

    Parameters
    ----------
    d_c : ndarray, shape (n', n, K)
        Posture error of candidate l at t' against reference frame t (radians); ``inf`` marks
        absent candidates.
    window : int
        w >= 1.
    band : int
        beta, reference frames either side of the diagonal.
    min_step : int
        0 lets C hold still (slower performer than the reference's frame rate allows).

    Returns
    -------
    C : ndarray of int, shape (n',)
        Reference frame per video frame, relative to the segment start.
    ell : ndarray of int, shape (n',)
        Selected candidate.
    cost : float
        Sum of the step costs (E_F times n'); ``inf`` when no path exists.
    """
    n_v, n_r, k = d_c.shape
    if n_v == 1:
        l0 = int(np.argmin(d_c[0, 0]))
        return np.zeros(1, dtype=int), np.array([l0]), float(d_c[0, 0, l0])
    diag = np.linspace(0.0, n_r - 1, n_v)
    t_idx = np.arange(n_r)
    D = np.full((n_r, k), np.inf)
    D[0] = d_c[0, 0]
    back_i = np.zeros((n_v, n_r, k), dtype=np.int32)
    back_k = np.zeros((n_v, n_r, k), dtype=np.int32)
    for tp in range(1, n_v):
        allowed = np.abs(t_idx - diag[tp]) <= band
        if tp == n_v - 1:
            allowed = t_idx == n_r - 1
        cur = d_c[tp]  # (n, K)
        best = np.full((n_r, k), np.inf)
        bi = np.zeros((n_r, k), dtype=np.int32)
        bk = np.zeros((n_r, k), dtype=np.int32)
        for i in range(min_step, window + 1):
            if i >= n_r:
                break
            prev_D = np.full((n_r, k), np.inf)
            prev_e = np.zeros((n_r, k))
            prev_D[i:] = D[: n_r - i]
            prev_e[i:] = d_c[tp - 1, : n_r - i]
            # (n, K_prev, K): D(t'-1, t-i, k) + (d_c(t', t, l) - d_c(t'-1, t-i, k))^2
            with np.errstate(invalid="ignore"):
                diff = cur[:, None, :] - prev_e[:, :, None]
            tot = prev_D[:, :, None] + np.where(np.isfinite(diff), diff * diff, np.inf)
            kk = np.argmin(tot, axis=1)
            val = np.take_along_axis(tot, kk[:, None, :], 1)[:, 0]
            better = val < best
            best = np.where(better, val, best)
            bi = np.where(better, i, bi)
            bk = np.where(better, kk, bk)
        D = np.where(allowed[:, None], best + cur, np.inf)
        back_i[tp], back_k[tp] = bi, bk
    l_end = int(np.argmin(D[n_r - 1]))
    cost = float(D[n_r - 1, l_end])
    C = np.empty(n_v, dtype=int)
    ell = np.empty(n_v, dtype=int)
    C[-1], ell[-1] = n_r - 1, l_end
    for tp in range(n_v - 1, 0, -1):
        i, kk = back_i[tp, C[tp], ell[tp]], back_k[tp, C[tp], ell[tp]]
        C[tp - 1], ell[tp - 1] = C[tp] - i, kk
    return C, ell, cost


def _segment_table(ref_dirs: np.ndarray, cand_dirs: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """d_c(t', t, l) for one segment, shape (n', n, K) (eq. 4.25)."""
    out = np.empty((cand_dirs.shape[0], ref_dirs.shape[0], cand_dirs.shape[1]))
    for i in range(cand_dirs.shape[0]):
        out[i] = _angles(ref_dirs[:, None], cand_dirs[i][None]).mean(-1)
    return np.where(valid[:, None, :], out, np.inf)


def _segment_path(
    ev: _Evidence,
    span: tuple[int, int],
    bound: tuple[int, int],
    fps_ratio: float,
    s: SelectionSettings,
) -> tuple[np.ndarray, np.ndarray, float]:
    """C (n',) relative to the reference start, candidates l (n',) and the path cost of one
    segment (thesis 4.7.2), the performer's frames ``span`` against the reference's ``bound``.

    The cost table is d_c of eq. 4.25 plus the image evidence and the anchor to stage 2's C
    (beyond the thesis, see :class:`SelectionSettings`).
    """
    (ps, pe), (rs, re) = span, bound
    n_seg_v, n_seg_r = pe - ps + 1, re - rs + 1
    table = _segment_table(
        ev.ref_dirs[rs : re + 1], ev.cand_dirs[ps : pe + 1], ev.valid[ps : pe + 1]
    )
    table = table + ev.image[ps : pe + 1, None, :]
    if s.anchor_deg_per_frame > 0:
        off = np.abs(np.arange(n_seg_r)[None, :] - (ev.C0[ps : pe + 1, None] - rs))
        table = table + np.radians(s.anchor_deg_per_frame) * (off / fps_ratio)[..., None]
    min_step = 1 if n_seg_r >= n_seg_v else 0
    window = max(1, int(np.ceil(s.window_k * n_seg_r / max(n_seg_v, 1))))
    band = max(window, int(np.ceil(s.band * n_seg_r)))
    c_loc, l_loc, cost = refine_segment(table, window=window, band=band, min_step=min_step)
    if not np.isfinite(cost):  # band too narrow for this segment: search the whole segment
        c_loc, l_loc, cost = refine_segment(table, window=n_seg_r, band=n_seg_r, min_step=0)
    return c_loc, l_loc, cost


def _refine_segments(
    ev: _Evidence,
    seg: _Segmentation,
    fps_ratio: float,
    s: SelectionSettings,
    on_progress: ProgressFn | None,
) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """The DP of thesis 4.7.2 per segment: C (T',), selected candidates l (T',) and each
    segment's mean step cost E_F (eq. 4.24)."""
    C = np.zeros(ev.n_frames, dtype=int)
    ell = np.zeros(ev.n_frames, dtype=int)
    costs = []
    for i, ((ps, pe), (rs, re)) in enumerate(zip(seg.spans, seg.bounds, strict=True)):
        c_loc, l_loc, cost = _segment_path(ev, (ps, pe), (rs, re), fps_ratio, s)
        # boundary frames are shared by two segments: the later segment's start wins
        C[ps : pe + 1] = rs + c_loc
        ell[ps : pe + 1] = l_loc
        costs.append(cost / (pe - ps + 1))
        if on_progress:
            on_progress("selection", 0.2 + 0.8 * (i + 1) / len(seg.bounds))
    return C, ell, costs


# --------------------------------------------------------------------------- 6.6, 6.7


def _frame_flags(
    seg: _Segmentation,
    eps: np.ndarray,
    large: float,
    candidate_flags: Sequence[Sequence[str]] | None,
) -> list[list[str]]:
    """Flags per video frame: stage 3's, then large errors (eps (T',) above ``large``
    radians), segment boundaries and the frames of missing or extra segments (6.6)."""
    flags: list[list[str]] = [
        list(candidate_flags[t]) if candidate_flags else [] for t in range(eps.shape[0])
    ]
    for t in np.flatnonzero(eps > large):
        flags[t].append("large_error")
    for i, (ps, pe) in enumerate(seg.spans):
        if i > 0:
            flags[ps].append("segment_boundary" if seg.found[i] else "segment_boundary_estimated")
        if seg.status[i] != "ok":
            for frame in range(ps, pe + 1):
                flags[frame].append(f"{seg.status[i]}_segment")
    return flags


def _segment_reports(
    seg: _Segmentation,
    eps: np.ndarray,
    bone_err: np.ndarray,
    costs: list[float],
) -> list[SegmentReport]:
    """One report per segment, its statistics over the frames it owns (:func:`owned_frames`)
    of the posture errors eps (T',) and bone errors (T', 16)."""
    owned = owned_frames(seg.spans)
    reports = []
    for i, ((ps, pe), (rs, re)) in enumerate(zip(seg.spans, seg.bounds, strict=True)):
        sl = slice(owned[i][0], owned[i][1] + 1)
        reports.append(
            SegmentReport(
                reference_start=int(rs), reference_end=int(re),
                performer_start=int(ps), performer_end=int(pe),
                initial_performer_start=int(seg.initial[i]), name=seg.names[i],
                status=seg.status[i], boundary_found=bool(seg.found[i]),
                tempo=float(seg.tempo[i]), mean_error=float(eps[sl].mean()),
                bone_mean_errors=bone_err[sl].mean(0), worst_frame=ps + int(np.argmax(eps[sl])),
                cost=float(costs[i]),
            )
        )  # fmt: skip
    return reports


def _messages(eps: np.ndarray, large: float, reports: list[SegmentReport]) -> list[str]:
    """Overall messages: a performer very different everywhere (6.7) gets one message
    instead of per-bone noise; missing and extra segments are named (6.6)."""
    messages = []
    if float(eps.mean()) > large:
        messages.append(
            f"Your motion is very different from the reference (mean posture error "
            f"{np.degrees(eps.mean()):.0f} deg): detailed per-bone errors are not meaningful; "
            "check that you performed the same motion, filmed from the expected side."
        )
    for i, r in enumerate(reports):
        if r.status == "missing":
            messages.append(f"Segment {r.name or i + 1} seems to be missing.")
        elif r.status == "extra_motion":
            messages.append(f"Segment {r.name or i + 1} seems to contain extra motion.")
    return messages


# --------------------------------------------------------------------------- public


def owned_frames(spans: Sequence[tuple[int, int]]) -> list[tuple[int, int]]:
    """The frames ``(first, last)`` each performer segment ``(start, end)`` owns.

    Consecutive segments share their boundary frame, and the later one owns it (its DP sets
    that frame's C and candidate), so every segment but the last ends one frame early unless
    it has a single frame.
    """
    last = len(spans) - 1
    return [(ps, pe - 1 if i < last and pe > ps else pe) for i, (ps, pe) in enumerate(spans)]


def smooth_errors(
    bone_err: np.ndarray,
    owned: Sequence[tuple[int, int]],
    sigma_frames: float,
    median_frames: int = 1,
) -> np.ndarray:
    """Each bone's error (T', 16) over time: a running median of ``median_frames``, then a
    Gaussian of std ``sigma_frames``.

    Within each segment's own frames ``owned`` (:func:`owned_frames`) only: thesis 2.1.3
    item 6 and 2.1.6 D, the motion is smooth within a segment so its posture errors change
    slowly there, and they may change at its boundaries. The median drops a frame whose
    selected candidate jumped alone (the Gaussian alone would spread that spike over its
    neighbours). Near a segment's ends the Gaussian is cut there and renormalised, so an end
    frame's error is neither pulled towards zero nor counted more than once.
    """
    if sigma_frames <= 0 and median_frames <= 1:
        return bone_err
    out = bone_err.copy()
    for first, last in owned:
        if last <= first:
            continue
        x = bone_err[first : last + 1]
        if median_frames > 1:
            x = median_filter(x, size=(median_frames, 1), mode="nearest")
        if sigma_frames > 0:
            num = gaussian_filter1d(x, sigma_frames, axis=0, mode="constant")
            den = gaussian_filter1d(np.ones(len(x)), sigma_frames, mode="constant")
            x = num / den[:, None]
        out[first : last + 1] = x
    return out


def select_and_refine(
    candidates: Sequence[np.ndarray],
    reference_joints: np.ndarray,
    reference_segments: Segments,
    C_initial: np.ndarray,
    *,
    settings: SelectionSettings | None = None,
    fps_ratio: float = 1.0,
    video_fps: float = 30.0,
    candidate_flags: Sequence[Sequence[str]] | None = None,
    candidate_d_s: Sequence[np.ndarray] | None = None,
    on_progress: ProgressFn | None = None,
) -> Selection:
    """Stage 4: boundaries, candidate selection, refined C and posture errors (thesis 4.7).

    Parameters
    ----------
    candidates : list of ndarray, shape (K_t', 17, 3) each
        Posture candidates per video frame, world frame (stage 3).
    reference_joints : ndarray, shape (T, 17, 3)
        Reference postures B_t.
    reference_segments : Segments
        Reference boundaries T_b (frame numbers of ``reference_joints``).
    C_initial : ndarray, shape (T',)
        Approximate correspondence from stage 2 (may be fractional).
    settings : SelectionSettings, optional
    fps_ratio : float
        Reference fps / video fps, for tempo.
    video_fps : float
        Frames per second of the video, for ``settings.error_smoothing_s``.
    candidate_flags : list of list of str, optional
        Stage-3 flags per video frame, passed through.
    candidate_d_s : list of ndarray, shape (K_t',) each, optional
        d_S of each candidate against its frame's body region (stage 3). When given, the
        candidate cost carries the image evidence (``settings.image_weight``) and candidates
        beyond ``settings.image_margin`` of their frame's best are dropped.
    on_progress : callable(stage, fraction), optional

    Returns
    -------
    Selection

    Raises
    ------
    InvalidInput
        On shapes, segments outside the reference or a non-positive ``fps_ratio``.
    """
    s = settings or SelectionSettings()
    cands, ref, C0 = _validate(
        candidates, reference_joints, reference_segments, C_initial, fps_ratio
    )
    _check_settings(s, video_fps)
    ev = _evidence(cands, ref, C0, candidate_d_s, s)
    seg = _segment_performer(ev, reference_segments, fps_ratio, s, on_progress)  # 4.7.1, 6.6
    C, ell, costs = _refine_segments(ev, seg, fps_ratio, s, on_progress)  # 4.7.2

    # eps_t' = d_B(B_C(t'), B'_t') per bone, smoothed within segments (2.1.3 item 6)
    frames = np.arange(ev.n_frames)
    bone_err = _angles(ev.ref_dirs[C], ev.cand_dirs[frames, ell])
    bone_err = smooth_errors(
        bone_err, owned_frames(seg.spans), s.error_smoothing_s * video_fps, s.error_median_frames
    )
    eps = bone_err.mean(-1)

    large = np.radians(s.large_error_deg)
    flags = _frame_flags(seg, eps, large, candidate_flags)
    reports = _segment_reports(seg, eps, bone_err, costs)
    return Selection(
        performer_segments=Segments(tuple(seg.starts), ev.n_frames - 1, seg.names),
        C=C, selected=ell, joints=ev.cand_joints[frames, ell], posture_error=eps,
        bone_errors=bone_err, flags=tuple(tuple(f) for f in flags), segments=tuple(reports),
        messages=tuple(_messages(eps, large, reports)),
    )  # fmt: skip


__all__ = ["Selection", "SelectionSettings", "SegmentReport", "refine_segment", "select_and_refine"]
