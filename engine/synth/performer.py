"""A synthetic performer in one call: timing, articulation, yaw, camera, video and truth."""

from __future__ import annotations

import numpy as np

from engine.body.kinematics import bone_vectors, rot_y
from engine.errors import InvalidInput
from engine.synth.articulation import (
    ARTICULABLE_PARTS,
    _joints_from_bones,
    _wrong_segments,
    articulate,
)
from engine.synth.film import _film, fit_camera
from engine.synth.settings import ReferenceLike, SynthCase, SynthSettings, _check, resolve_parts
from engine.synth.timing import reference_segments, time_warp
from engine.synth.truth import _truth
from engine.types import Motion, Segments


def synthesize(
    reference: ReferenceLike,
    *,
    settings: SynthSettings,
    rng: np.random.Generator,
    segments: Segments | None = None,
) -> SynthCase:
    """Make a performer video of a reference motion with exact ground truth.

    Parameters
    ----------
    reference : Reference
        ``.motion`` (joints (T, 17, 3), fps, first_motion_frame) and ``.shape``.
    settings : SynthSettings
    rng : numpy.random.Generator
        Source of every random choice (warp, wrong segments, parts, axes, background, noise).
    segments : Segments, optional
        Reference segments; :func:`reference_segments` when omitted.

    Returns
    -------
    SynthCase

    Raises
    ------
    InvalidInput
        A reference that is too short, segments outside it, fps above the reference's.
    """
    motion, shape = reference.motion, reference.shape
    segments = _checked_segments(motion, settings, segments)
    allowed = resolve_parts(
        settings.error_parts if settings.error_parts is not None else ARTICULABLE_PARTS
    )
    warp, knots_video, speeds = time_warp(
        segments, motion.fps, settings.fps, settings.warp_strength, rng
    )
    truncated = settings.max_frames is not None and len(warp) > settings.max_frames
    if truncated:
        warp = warp[: settings.max_frames]
    ref = _reference_at(reference, warp)
    art = _wrong_segments(warp, segments, shape.offsets, allowed, settings, rng)
    joints = articulate(ref, shape.offsets, art.angles, art.axes)
    if settings.yaw_deg:
        vec = np.einsum("ij,nbj->nbi", rot_y(np.radians(settings.yaw_deg)), bone_vectors(joints))
        joints = _joints_from_bones(joints[:, 0], vec)
    camera = fit_camera(joints, shape, settings)
    frames, masks = _film(joints, shape, camera, settings, rng)
    truth = _truth(
        motion, settings, segments, warp, knots_video, speeds, ref, joints, camera,
        art.wrong, art.seg_parts, art.seg_of, truncated,
    )  # fmt: skip
    return SynthCase(
        frames=frames,
        masks=masks,
        joints_3d=joints,
        warp=warp,
        camera=camera,
        fps=float(settings.fps),
        truth=truth,
    )


def _checked_segments(
    motion: Motion, settings: SynthSettings, segments: Segments | None
) -> Segments:
    """The reference segments to warp (:func:`reference_segments` when omitted), after
    checking the reference's joints (T >= 3, 17, 3) and frame rate against ``settings``."""
    if motion.joints.ndim != 3 or motion.joints.shape[1:] != (17, 3) or motion.frames < 3:
        raise InvalidInput(f"reference joints must be (T >= 3, 17, 3), got {motion.joints.shape}")
    _check(settings.fps <= motion.fps, "fps", f"<= the reference's {motion.fps:g}", settings.fps)
    if segments is None:
        segments = reference_segments(motion, settings.n_segments)
    if segments.starts[0] < 0 or segments.end > motion.frames - 1:
        raise InvalidInput(
            f"segments {segments.starts}..{segments.end} lie outside the reference's "
            f"{motion.frames} frames"
        )
    return segments


def _reference_at(reference: ReferenceLike, warp: np.ndarray) -> np.ndarray:
    """The reference postures B_C(t'), shape (T', 17, 3), at the fractional frames ``warp``."""
    from engine.io.bvh import Reference, sample_at, sample_reference

    # the file's own rotations interpolated, as the public truth does (rigid-part slerp
    # would bend CMU's spine and hips by up to 20 deg)
    if isinstance(reference, Reference):
        return sample_reference(reference, warp)
    # a reference built in memory (no file): interpolate on the 17-joint body
    return sample_at(reference.motion, reference.shape, warp)
