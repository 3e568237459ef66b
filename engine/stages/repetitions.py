"""Repetitions: where in a video the reference motion is performed, and how often.

Beyond the thesis, whose stage 2 (4.5) pins the first video frame to the reference's first
frame and the last to its last (6.3 lets them float a little). A real upload holds more:
squats come in sets, a golf clip may start with waggles and end with a walk. Here the
reference is matched as a subsequence of the video, as often as it occurs, by one Viterbi
pass over the states {idle} + {reference frames}:

- idle -> idle costs ``idle_cost`` per frame (the performer does something else);
- idle -> the reference's first frame starts a repetition, anywhere;
- reference frame c -> c + i, i = 0..w, advances it (w as stage 2's window);
- the reference's last frame -> idle (or straight to its first frame) ends it.

Every video frame is either idle or in a repetition, each repetition runs the whole
reference, and the total cost decides how many there are. ``idle_cost`` is what a frame
costs when it shows no part of the motion: the cost of a frame in a repetition is its d
(silhouette and keypoints, :func:`engine.stages.alignment.cost_entries`), so a frame whose d
against every reference posture is above ``idle_cost`` is better left out.

Status: the DP below is tested on synthetic cost matrices; the pipeline does not call it
yet. On the real squat clips, with d_A + d_K of the reference as calibrated (absolute, or
relative to each frame's best posture), it split 65 frames of four shallow squats into two
"repetitions" (the reference is one deep squat, and at 5 fps a descent takes one or two
frames), so it is not wired in. See docs/perception.md, "Repetitions".

:func:`excursions` is the cheaper cue that is wired in, in two places:

- :func:`performances` groups the excursions as the reference's own (seen through the
  calibrated camera) and widens each by the reference's rest before and after it; when the
  video holds two or more, :func:`engine.pipeline.run_stages_0_2` analyses the first and the
  result lists them all (``summary.repetitions``);
- where the reported motion leaves the body of a video that was not cut (``poor_fit``),
  :func:`engine.stages.assessment.assess_fit` names the whole repetitions it finds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.errors import InvalidInput


@dataclass(frozen=True)
class Repetition:
    """One performance of the whole reference found in the video.

    Attributes
    ----------
    start, end : int
        Video frames, ``end`` exclusive.
    mean_cost : float
        Mean d over its frames along the path.
    """

    start: int
    end: int
    mean_cost: float

    def to_dict(self) -> dict:
        return {"start": self.start, "end": self.end, "mean_cost": round(self.mean_cost, 4)}


def find_repetitions(
    cost: np.ndarray, *, window: int, idle_cost: float, min_frames: int = 2
) -> list[Repetition]:
    """Every performance of the reference in the video (subsequence DP, see the module).

    Parameters
    ----------
    cost : ndarray, shape (T', N)
        d(t', c) of each video frame against N reference frames in order (a coarse stride
        of the reference is fine; ``window`` counts in these columns).
    window : int
        Largest advance in reference columns per video frame, >= 1.
    idle_cost : float
        Cost of a video frame that belongs to no repetition.
    min_frames : int
        Shortest repetition kept, video frames.

    Returns
    -------
    list of Repetition
        In video order; empty when no whole performance fits.

    Raises
    ------
    InvalidInput
        Bad shapes or parameters.
    """
    d = np.asarray(cost, dtype=float)
    if d.ndim != 2 or d.shape[0] < 1 or d.shape[1] < 2:
        raise InvalidInput(f"cost must be a (T', N >= 2) matrix, got shape {d.shape}")
    if not isinstance(window, int | np.integer) or window < 1:
        raise InvalidInput(f"window must be an integer >= 1, got {window!r}")
    if not np.isfinite(idle_cost):
        raise InvalidInput(f"idle_cost must be finite, got {idle_cost!r}")
    n_v, n_c = d.shape
    d = np.where(np.isfinite(d), d, np.inf)
    # state n_c is idle; back[t, s] is the state at t - 1 on the best path into s at t
    D = np.full(n_c + 1, np.inf)
    D[0], D[n_c] = d[0, 0], idle_cost
    back = np.zeros((n_v, n_c + 1), dtype=np.int32)
    cols = np.arange(n_c)
    for t in range(1, n_v):
        best = np.full(n_c + 1, np.inf)
        arg = np.zeros(n_c + 1, dtype=np.int32)
        for i in range(0, window + 1):  # advance by i columns
            if i >= n_c:
                break
            cand = np.full(n_c, np.inf)
            cand[i:] = D[: n_c - i]
            better = cand < best[:n_c]
            best[:n_c][better] = cand[better]
            arg[:n_c][better] = cols[better] - i
        # a repetition starts at the reference's first frame, from idle or from a last frame
        for src in (n_c, n_c - 1):
            if D[src] < best[0]:
                best[0], arg[0] = D[src], src
        # idle from idle, or once a repetition has reached its last frame
        for src in (n_c, n_c - 1):
            if D[src] < best[n_c]:
                best[n_c], arg[n_c] = D[src], src
        back[t] = arg
        D = best + np.append(d[t], idle_cost)
    end = n_c if D[n_c] <= D[n_c - 1] else n_c - 1
    path = np.empty(n_v, dtype=np.int64)
    path[-1] = end
    for t in range(n_v - 1, 0, -1):
        path[t - 1] = back[t, path[t]]
    return _runs(path, d, n_c, min_frames)


def _runs(path: np.ndarray, d: np.ndarray, n_c: int, min_frames: int) -> list[Repetition]:
    """The complete repetitions of a state path (T',): runs from column 0 to column n_c - 1.

    Frames held at the first or last column stay in the repetition: a reference may itself
    hold a posture for a while (P2's first second moves 1 mm a frame), and only the frames
    that match no reference posture at all are idle."""
    out = []
    t, n_v = 0, len(path)
    while t < n_v:
        if path[t] != 0:
            t += 1
            continue
        u = t
        while u + 1 < n_v and path[u + 1] != n_c and path[u + 1] >= path[u]:
            u += 1
        if path[u] == n_c - 1 and u + 1 - t >= min_frames:
            rows = np.arange(t, u + 1)
            out.append(Repetition(int(t), int(u + 1), float(d[rows, path[rows]].mean())))
        t = u + 1
    return out


#: Left/right joint pairs (DESIGN.md order) whose midpoints describe a posture whatever side
#: the detector calls left: hips, knees, ankles, shoulders, elbows, wrists.
_SIDE_PAIRS = ((1, 4), (2, 5), (3, 6), (9, 12), (10, 13), (11, 14))
_HIP, _NECK = 0, 15


def posture_descriptor(joints_2d: np.ndarray) -> np.ndarray:
    """Side midpoints and the neck, relative to the hip and in body heights.

    Parameters
    ----------
    joints_2d : ndarray, shape (T', 17, 2)
        Image positions (keypoints, or projected joints); NaN where unknown.

    Returns
    -------
    ndarray, shape (T', 7, 2)
        Unchanged by a left/right swap of the labels (the detector swaps in 10-66 % of the
        frames, docs/perception.md) and by where the performer stands or how large he is.
    """
    j = np.asarray(joints_2d, dtype=float)
    mids = [np.nanmean(j[:, list(p)], axis=1) for p in _SIDE_PAIRS] + [j[:, _NECK]]
    ankles_to_neck = np.linalg.norm(mids[2] - j[:, _NECK], axis=-1)
    height = np.nanmedian(ankles_to_neck) if np.isfinite(ankles_to_neck).any() else np.nan
    return (np.stack(mids, axis=1) - j[:, _HIP][:, None]) / max(float(height), 1e-9)


#: Smallest posture change that counts as leaving the rest posture, in body heights: well
#: above keypoint noise (~0.01), well below a squat's or a swing's (0.25-0.4 on the real clips).
MIN_EXCURSION = 0.05


def excursions(
    keypoints: np.ndarray, start_posture: np.ndarray, fps: float, *, min_s: float = 0.4
) -> list[Repetition]:
    """Where the performer leaves the reference's starting posture and comes back to it.

    Beyond the thesis. A cheaper cue than :func:`find_repetitions` for a video that holds
    several repetitions of a one-repetition reference (docs/perception.md, "Repetitions"):
    the distance e(t') of each frame's :func:`posture_descriptor` to the rest posture, and
    the runs where e exceeds half its 95th percentile (and :data:`MIN_EXCURSION`). The rest
    posture is the median of the video frames closest to the reference's first posture (a
    fifth of them): the reference says which posture is the start, the video how this
    performer holds it. Runs under half the typical one's length are something else.

    Parameters
    ----------
    keypoints : ndarray, shape (T', 17, 2)
    start_posture : ndarray, shape (17, 2)
        The reference's first posture as the calibrated camera sees it.
    fps : float
    min_s : float
        Shortest excursion kept, seconds.

    Returns
    -------
    list of Repetition
        Complete excursions only (the performer leaves the rest posture after the video
        starts and is back before it ends), in video order; ``mean_cost`` is the
        excursion's mean e.
    """
    x = posture_descriptor(keypoints)
    ref = posture_descriptor(np.asarray(start_posture, dtype=float)[None])[0]
    to_ref = np.sqrt(np.nanmean(np.sum((x - ref) ** 2, axis=-1), axis=-1))
    if not np.isfinite(to_ref).any():
        return []
    near = to_ref <= np.nanpercentile(to_ref, 20)
    rest = np.nanmedian(x[near], axis=0)
    e = np.nan_to_num(np.sqrt(np.nanmean(np.sum((x - rest) ** 2, axis=-1), axis=-1)))
    away = e > max(0.5 * np.percentile(e, 95), MIN_EXCURSION)
    out, t, n = [], 0, len(e)
    while t < n:
        if not away[t]:
            t += 1
            continue
        start = t
        while t < n and away[t]:
            t += 1
        # whole only: seen leaving the rest posture and coming back to it inside the video
        if 0 < start and t < n and (t - start) / fps >= min_s:
            out.append(Repetition(start, t, float(e[start:t].mean())))
    # a repetition lasts about as long as the others: half the typical one is something else
    # (re-racking a bar, a step to the side)
    typical = float(np.median([r.end - r.start for r in out])) if out else 0.0
    return [r for r in out if r.end - r.start >= 0.5 * typical]


#: Slowest and fastest pace of a performance against the reference's (either way).
MAX_PACE = 3.0


@dataclass(frozen=True)
class Performances:
    """The whole performances of the reference a video holds (:func:`performances`).

    Attributes
    ----------
    found : tuple of Repetition
        Each performance as video frames ``start``..``end`` (exclusive), with the rest
        before and after it that the reference itself holds; in video order.
    per_performance : int
        Excursions from the starting posture one performance makes (the reference's own
        count: one for a squat).
    """

    found: tuple[Repetition, ...]
    per_performance: int

    def to_dicts(self, fps: float, analysed: int | None, offset: int = 0) -> list[dict]:
        """``summary.repetitions`` of the result: file frames, seconds, which one is analysed."""
        return [
            {"start": r.start + offset, "end": r.end + offset,
             "start_s": round((r.start + offset) / fps, 2),
             "end_s": round((r.end + offset) / fps, 2), "analysed": i == analysed}
            for i, r in enumerate(self.found)
        ]  # fmt: skip


def performances(
    keypoints: np.ndarray,
    reference_2d: np.ndarray,
    fps: float,
    reference_fps: float,
    *,
    min_s: float = 0.4,
) -> Performances:
    """Every whole performance of the reference in the video, when it holds several.

    Beyond the thesis (whose stage 2 matches one performance to the whole video). The
    reference tells what one performance looks like in the keypoints' own terms: seen
    through the calibrated camera, it leaves its first posture and comes back ``m`` times
    (:func:`excursions`; once for a squat), after a lead-in and before a tail at rest. The
    video's excursions, taken ``m`` at a time, are its performances; each is widened by the
    reference's lead-in and tail at the performance's own pace (video excursion time over
    the reference's), up to halfway to its neighbours, so stage 2's pinned ends (C(0) = the
    first reference frame, C(L') = the last) hold on each of them.

    Parameters
    ----------
    keypoints : ndarray, shape (T', 17, 2)
        The pose model's keypoints; NaN where none.
    reference_2d : ndarray, shape (T, 17, 2)
        The reference's motion (from its first motion frame) projected by the calibrated
        camera.
    fps, reference_fps : float
    min_s : float
        Shortest excursion kept, seconds (of the video and of the reference).

    Returns
    -------
    Performances
        ``found`` is empty unless the video holds at least two whole performances (one
        performance is what stage 2 already assumes).

    Raises
    ------
    InvalidInput
        Shapes that do not match or a non-positive rate.
    """
    kp, ref = np.asarray(keypoints, float), np.asarray(reference_2d, float)
    if kp.ndim != 3 or kp.shape[1:] != (17, 2) or ref.ndim != 3 or ref.shape[1:] != (17, 2):
        raise InvalidInput(
            f"keypoints and reference_2d must be (T, 17, 2), got {kp.shape} and {ref.shape}"
        )
    if not (fps > 0 and reference_fps > 0):
        raise InvalidInput(f"fps and reference_fps must be > 0, got {fps} and {reference_fps}")
    own = excursions(ref, ref[0], reference_fps, min_s=min_s)
    if not own:
        return Performances((), 0)
    m = len(own)
    seen = excursions(kp, ref[0], fps, min_s=min_s)
    ref_moving = max((own[-1].end - own[0].start) / reference_fps, 1e-9)
    groups = [seen[i : i + m] for i in range(0, len(seen) - m + 1, m)]
    # (start, end, mean e, pace: video seconds per reference second) of each group
    spans = [
        (g[0].start, g[-1].end, float(np.mean([r.mean_cost for r in g])),
         (g[-1].end - g[0].start) / fps / ref_moving)
        for g in groups
    ]  # fmt: skip
    # a performance takes between a third and three times the reference's time (stage 2's
    # window allows no more); anything else is another motion
    spans = [sp for sp in spans if 1 / MAX_PACE <= sp[3] <= MAX_PACE]
    if len(spans) < 2:
        return Performances((), m)
    lead, tail = own[0].start / reference_fps, (len(ref) - own[-1].end) / reference_fps
    found = []
    for i, (start, end, cost, pace) in enumerate(spans):
        lo = 0 if i == 0 else (spans[i - 1][1] + start) // 2
        hi = len(kp) if i == len(spans) - 1 else (end + spans[i + 1][0] + 1) // 2
        a = max(lo, int(round(start - lead * pace * fps)))
        b = min(hi, int(round(end + tail * pace * fps)))
        found.append(Repetition(a, b, cost))
    return Performances(tuple(found), m)
