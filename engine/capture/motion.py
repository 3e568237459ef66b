"""Capture step 3: the lifted segments as a motion of the 17-joint body, with root motion.

The segments' directions are smoothed without lag, then laid onto the engine's skeleton with
constant bone lengths (the default adult body scaled to the performer's height), so the motion
writes to BVH exactly. The root moves with the hips' image position and, in depth, with the
body's image scale (weak perspective: scale = focal / distance). The world frame is DESIGN.md's:
y up, the body facing +z at frame 0, the floor at y = 0.
"""

from __future__ import annotations

import numpy as np

from engine.body.kinematics import rot_y
from engine.body.shapes import BodyShape
from engine.body.skeleton import JOINT_INDEX as J
from engine.capture.lifting import Lifted, S
from engine.capture.pose2d import P, Pose2D, zero_phase

#: Camera (x right, y down, z away) -> a world with y up and z towards the camera.
_CAM_TO_WORLD = np.diag([1.0, -1.0, -1.0])
#: The default body's droop of the hip bones and rise of the clavicles (engine.body.shapes).
_HIP_DROOP = np.arctan(0.35)
_CLAVICLE_RISE = np.arctan(0.25)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


def _across(v: np.ndarray, up: np.ndarray) -> np.ndarray:
    """The part of ``v`` perpendicular to the unit ``up``, normalised."""
    return _unit(v - np.sum(v * up, -1, keepdims=True) * up)


def skeleton_joints(vectors: np.ndarray, shape: BodyShape) -> np.ndarray:
    """The 17 joints (T', 17, 3), relative to the hip, from lifted segments (T', 12, 3).

    The spine is straight along the trunk; the hip bones and clavicles leave it as in the
    default body; every limb bone takes its segment's direction and the body's own length.
    """
    L = shape.lengths
    v = vectors
    up = _unit(v[:, S["trunk"]])
    lat_h = _across(v[:, S["pelvis"]], up)
    lat_s = _across(v[:, S["shoulders"]], up)
    T = v.shape[0]
    j = np.zeros((T, 17, 3))
    hip_l = np.cos(_HIP_DROOP) * lat_h - np.sin(_HIP_DROOP) * up
    hip_r = -np.cos(_HIP_DROOP) * lat_h - np.sin(_HIP_DROOP) * up
    j[:, J["l_hip"]] = L[0] * hip_l
    j[:, J["r_hip"]] = L[3] * hip_r
    for side, (kb, ab) in {"l": (1, 2), "r": (4, 5)}.items():
        j[:, J[f"{side}_knee"]] = j[:, J[f"{side}_hip"]] + L[kb] * _unit(v[:, S[f"{side}_thigh"]])
        j[:, J[f"{side}_ankle"]] = j[:, J[f"{side}_knee"]] + L[ab] * _unit(v[:, S[f"{side}_shin"]])
    j[:, J["lower_chest"]] = L[6] * up
    j[:, J["upper_chest"]] = j[:, J["lower_chest"]] + L[7] * up
    for side, (cb, ub, fb), sgn in (("l", (8, 9, 10), 1.0), ("r", (11, 12, 13), -1.0)):
        clav = sgn * np.cos(_CLAVICLE_RISE) * lat_s + np.sin(_CLAVICLE_RISE) * up
        sh = j[:, J["upper_chest"]] + L[cb] * clav
        j[:, J[f"{side}_shoulder"]] = sh
        j[:, J[f"{side}_elbow"]] = sh + L[ub] * _unit(v[:, S[f"{side}_upper_arm"]])
        j[:, J[f"{side}_wrist"]] = j[:, J[f"{side}_elbow"]] + L[fb] * _unit(
            v[:, S[f"{side}_forearm"]]
        )
    j[:, J["neck"]] = j[:, J["upper_chest"]] + L[14] * up
    j[:, J["head_top"]] = j[:, J["neck"]] + L[15] * _unit(v[:, S["head"]])
    return j


def root_positions(
    pose: Pose2D, scale: np.ndarray, width: int, height: int, distance_m: float
) -> np.ndarray:
    """The hip's path (T', 3) in the camera frame, metres: image position over scale, and a
    depth that grows as the body's image shrinks (``distance_m`` at frame 0)."""
    uv = pose.uv[:, P["hip"]] - np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    xy = uv / scale[:, None]
    z = distance_m * scale[0] / scale
    return np.concatenate([xy, z[:, None]], axis=1)


def world_motion(
    lifted: Lifted,
    pose: Pose2D,
    shape: BodyShape,
    width: int,
    height: int,
    distance_m: float,
    cutoff_hz: float,
) -> np.ndarray:
    """The captured motion (T', 17, 3) in DESIGN.md's world frame, metres."""
    vec = zero_phase(_unit(lifted.vectors), pose.fps, cutoff_hz)
    rel = skeleton_joints(vec, shape)
    root = zero_phase(
        root_positions(pose, lifted.scale, width, height, distance_m), pose.fps, cutoff_hz
    )
    joints = (rel + root[:, None]) @ _CAM_TO_WORLD.T
    # heading: the body faces +z at frame 0 (DESIGN.md "Frames of reference")
    f = np.cross(joints[0, J["l_hip"]] - joints[0, J["r_hip"]], [0.0, 1.0, 0.0])
    R = rot_y(float(np.arctan2(-f[0], f[2]))) if np.hypot(f[0], f[2]) > 1e-9 else np.eye(3)
    joints = (joints - joints[0, J["hip"]] * np.array([1.0, 0.0, 1.0])) @ R.T
    feet = joints[:, [J["l_ankle"], J["r_ankle"]], 1].min()
    return joints - np.array([0.0, feet - 0.08, 0.0])  # ankles ~8 cm above the floor
