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

:func:`excursions` is the cheaper cue that is wired in: where the reported motion leaves the
body (``poor_fit``), :func:`engine.stages.assessment.assess_fit` names the whole repetitions
it finds, so the performer knows where to trim.
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
        Complete excursions only (the performer is back at rest before the video ends), in
        video order; ``mean_cost`` is the excursion's mean e.
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
        if t < n and (t - start) / fps >= min_s:
            out.append(Repetition(start, t, float(e[start:t].mean())))
    # a repetition lasts about as long as the others: half the typical one is something else
    # (re-racking a bar, a step to the side)
    typical = float(np.median([r.end - r.start for r in out])) if out else 0.0
    return [r for r in out if r.end - r.start >= 0.5 * typical]
