"""What stage 4 compares, checked and prepared once: the candidates padded per frame, their
bone directions and the reference's, and the image evidence of each candidate.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from engine.body.kinematics import bone_directions
from engine.body.skeleton import JOINT_INDEX, N_JOINTS
from engine.errors import InvalidInput
from engine.stages.selection.settings import SelectionSettings
from engine.types import Segments


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
