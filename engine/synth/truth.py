"""The ground truth of a synthetic case: the ``truth.json`` dictionary of DESIGN.md
("Synthetic cases") plus the public cases' extra fields.
"""

from __future__ import annotations

import numpy as np

from engine.body.skeleton import BONE_NAMES, BONES, JOINTS, PART_ROOT_JOINT, PARTS
from engine.measures import bone_angles
from engine.render.camera import Camera
from engine.synth.settings import SynthSettings
from engine.types import Motion, Segments


def _truth(
    motion: Motion,
    settings: SynthSettings,
    segments: Segments,
    warp: np.ndarray,
    knots_video: np.ndarray,
    speeds: np.ndarray,
    ref: np.ndarray,
    joints: np.ndarray,
    camera: Camera,
    wrong: np.ndarray,
    seg_parts: list[list[int]],
    seg_of: np.ndarray,
    truncated: bool,
) -> dict:
    """The DESIGN.md truth.json dictionary (plus the public cases' extra fields)."""
    bounds = [*segments.starts, segments.end]
    return {
        "version": 1,
        "fps": float(settings.fps),
        "reference_fps": float(motion.fps),
        "joints": list(JOINTS),
        "bones": [list(b) for b in BONES],
        "bone_names": list(BONE_NAMES),
        "camera": _camera(camera, settings),
        "frames": _frames(warp, ref, joints, camera, seg_of),
        "warp": [round(float(w), 6) for w in warp],
        "segments": [
            _segment(k, bounds, knots_video, speeds, bool(wrong[k]), seg_parts[k], settings)
            for k in range(len(segments.starts))
        ],
        "reference": {
            "name": motion.name,
            "frames": motion.frames,
            "fps": float(motion.fps),
            "first_motion_frame": motion.first_motion_frame,
        },
        "video": {
            "frames": len(warp),
            "fps": float(settings.fps),
            "width": camera.width,
            "height": camera.height,
        },
        "settings": {
            k: (list(v) if isinstance(v, tuple) else v) for k, v in settings.__dict__.items()
        },
        "notes": _notes(motion, settings, int(wrong.sum()), bounds, warp, truncated),
    }


def _camera(camera: Camera, settings: SynthSettings) -> dict:
    """The truth's ``camera`` block: the engine's camera and how it projects."""
    cam = camera.to_dict()
    cam.update(
        type="orthographic",
        R_cam_world=camera.R_cam_world.tolist(),
        pixel_convention="pixel centres at integer (u, v); u right, v down (OpenCV)",
        projection="u = cx + scale * (A_u . X), v = cy + scale * (A_v . X): engine Camera",
        fill_fraction_of_height=settings.fill,
    )
    return cam


def _frames(
    warp: np.ndarray, ref: np.ndarray, joints: np.ndarray, camera: Camera, seg_of: np.ndarray
) -> list[dict]:
    """One entry per video frame: the true C(t'), the performer's joints in 3D and in the
    image, and the bone errors against the reference postures ``ref`` (T', 17, 3)."""
    err = np.degrees(bone_angles(joints, ref))  # (T', 16)
    uv = camera.project(joints)
    return [
        {
            "t": i,
            "reference_frame": round(float(warp[i]), 6),
            "joints_3d": np.round(joints[i], 6).tolist(),
            "joints_2d": np.round(uv[i], 4).tolist(),
            "bone_errors_deg": np.round(err[i], 4).tolist(),
            "posture_error_deg": round(float(err[i].mean()), 4),
            "reference_segment": int(seg_of[i]),
        }
        for i in range(len(warp))
    ]


def _segment(
    k: int,
    bounds: list[int],
    knots_video: np.ndarray,
    speeds: np.ndarray,
    wrong: bool,
    parts: list[int],
    settings: SynthSettings,
) -> dict:
    """Segment k's entry: its reference and performer spans, speed, and what is wrong in it."""
    return {
        "reference_start": int(bounds[k]),
        "reference_end": int(bounds[k + 1]),
        "performer_start": round(float(knots_video[k]), 3),
        "performer_end": round(float(knots_video[k + 1]), 3),
        "speed": round(float(speeds[k]), 4),
        "wrong": wrong,
        "amplitude_deg": float(settings.error_deg) if wrong else 0.0,
        "articulated_parts": [PARTS[p] for p in parts],
        "articulated_joints": [JOINTS[int(PART_ROOT_JOINT[p])] for p in parts],
        "yaw_deg": float(settings.yaw_deg),
    }


def _notes(
    motion: Motion,
    settings: SynthSettings,
    n_wrong: int,
    bounds: list[int],
    warp: np.ndarray,
    truncated: bool,
) -> str:
    """The truth's ``notes``: how the case was made, in words."""
    notes = (
        f"synthetic performer of {motion.name or 'the reference'} by engine.synth: smooth "
        f"monotone warp (PCHIP through segment boundaries, per-segment speeds), "
        f"{n_wrong} wrong segment(s) with parts rotated {settings.error_deg:g} deg "
        f"about their root joints (smooth ramp {settings.ramp:g} of the segment), yaw "
        f"{settings.yaw_deg:g} deg. World frame = the reference's (metres, y up, facing +z at "
        f"reference frame 0). reference_frame = true fractional C(t'); bone_errors_deg = "
        "angle to the reference sampled at that frame (engine.io.bvh.sample_reference, "
        "slerp of the file's rotations). "
        f"joints_2d = exact projection of joints_3d by the camera (pixel centres on integers). "
        f"Video frame 0 is pinned to reference frame {bounds[0]} (the first motion frame)."
    )
    if truncated:
        notes += (
            f" Truncated to {len(warp)} video frames (max_frames): the video ends at "
            f"reference frame {warp[-1]:.2f}, before the reference's end {bounds[-1]}."
        )
    return notes
