"""Retargeting a reference motion to another body (thesis 2.1.1 item 3).

The reference's posture sequence is kept as part rotations (theta_t, relative to the default
posture) and root positions (p_t); only the time-independent body model H changes. Bone
directions are therefore preserved and bone lengths become the new body's. The root path is
scaled by the ratio of leg lengths so that steps keep their proportion to the new legs.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from engine.body.kinematics import forward_kinematics, part_rotations
from engine.body.shapes import BodyShape, default_radii
from engine.body.skeleton import BONE_NAMES, BONES
from engine.errors import InvalidInput
from engine.types import Motion

_LEG_BONES = np.array([1, 2, 4, 5])  # thighs and shins


def retarget_shape(
    shape: BodyShape, height: float, bone_lengths: Mapping[str, float] | None = None
) -> BodyShape:
    """A body with ``shape``'s proportions scaled to ``height``, optionally with given bones.

    Parameters
    ----------
    shape : BodyShape
        The reference's body.
    height : float
        Performer's standing height in metres (ankle to head top plus 4 %, the measure of
        :meth:`BodyShape.from_rest_joints`), in [0.5, 2.5].
    bone_lengths : mapping of str to float, optional
        Measured bone lengths in metres, keyed by bone name ``"l_shoulder->l_elbow"``
        (:data:`~engine.body.skeleton.BONE_NAMES`) or by the child joint ``"l_elbow"``;
        they replace the scaled ones. Left/right are independent.

    Returns
    -------
    BodyShape
        Same default-posture bone directions; capsule radii for ``height``.

    Raises
    ------
    InvalidInput
        When ``height`` is out of range or ``bone_lengths`` names an unknown bone or a
        non-positive length.
    """
    if not (isinstance(height, int | float) and np.isfinite(height) and 0.5 <= height <= 2.5):
        raise InvalidInput(f"height must be between 0.5 and 2.5 m, got {height!r}")
    rest = forward_kinematics(shape.offsets, np.zeros(3), np.broadcast_to(np.eye(3), (12, 3, 3)))
    own = float(rest[:, 1].max() - rest[:, 1].min()) * 1.04
    offsets = shape.offsets * (height / own)
    if bone_lengths:
        by_child = {c: b for b, (_, c) in enumerate(BONES)}
        by_name = {n: b for b, n in enumerate(BONE_NAMES)}
        for key, length in bone_lengths.items():
            b = by_name.get(key, by_child.get(key))
            if b is None:
                raise InvalidInput(
                    f"bone_lengths names unknown bone {key!r}; use e.g. {BONE_NAMES[9]!r} "
                    f"or its child joint {BONES[9][1]!r}"
                )
            if not (np.isfinite(length) and length > 0):
                raise InvalidInput(f"bone_lengths[{key!r}] must be positive, got {length!r}")
            offsets[b] *= length / np.linalg.norm(offsets[b])
    return BodyShape(offsets=offsets, radii=default_radii(float(height)))


def retarget(
    motion: Motion,
    shape: BodyShape,
    height: float,
    *,
    bone_lengths: Mapping[str, float] | None = None,
) -> tuple[Motion, BodyShape]:
    """The reference motion performed by a body of another size (thesis 2.1.1 item 3).

    Parameters
    ----------
    motion : Motion
        Reference postures, joints (T, 17, 3).
    shape : BodyShape
        The reference's body (its default posture defines the part rotations).
    height : float
        Performer's height, metres.
    bone_lengths : mapping, optional
        See :func:`retarget_shape`.

    Returns
    -------
    motion : Motion
        Joints (T, 17, 3): every bone keeps its direction of the original motion (exactly
        for single-bone parts, best rigid fit for the abdomen and upper chest), lengths are
        the new body's; the root path is scaled by the leg-length ratio about frame 0's root.
    shape : BodyShape
        The new body.

    Raises
    ------
    InvalidInput
        See :func:`retarget_shape`.
    """
    new = retarget_shape(shape, height, bone_lengths)
    R = part_rotations(motion.joints, shape.offsets)
    k = new.lengths[_LEG_BONES].sum() / shape.lengths[_LEG_BONES].sum()
    root0 = motion.joints[:1, 0]
    root = root0 + k * (motion.joints[:, 0] - root0)
    # keep the feet on the floor: scale the root height about the floor, not about frame 0
    floor = float(motion.joints[0, :, 1].min())
    root[:, 1] = floor + k * (motion.joints[:, 0, 1] - floor)
    joints = forward_kinematics(new.offsets, root, R)
    out = Motion(
        joints=joints, fps=motion.fps, name=motion.name,
        first_motion_frame=motion.first_motion_frame,
    )  # fmt: skip
    return out, new
