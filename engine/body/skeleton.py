"""The 17-joint body of the thesis (fig. 2.1, appendix A) and DESIGN.md's data contract.

Everything here is a constant table; arrays are read-only so no caller can change them.
Bone ``b`` runs from ``PARENTS[b + 1]`` to joint ``b + 1``: the joint order is topological
(every parent comes before its children), so forward kinematics is one pass over the bones.
"""

from __future__ import annotations

import numpy as np

JOINTS: tuple[str, ...] = (
    "hip", "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle", "lower_chest",
    "upper_chest", "l_shoulder", "l_elbow", "l_wrist", "r_shoulder", "r_elbow", "r_wrist",
    "neck", "head_top",
)  # fmt: skip
JOINT_INDEX: dict[str, int] = {name: i for i, name in enumerate(JOINTS)}
N_JOINTS = 17
N_BONES = 16
N_PARTS = 12


def _ro(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


#: Parent joint of each joint, shape (17,); -1 for the root.
PARENTS = _ro(np.array([-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 9, 10, 8, 12, 13, 8, 15]))
#: Bone endpoints, shape (16,) each: bone b = BONE_PARENT[b] -> BONE_CHILD[b].
BONE_CHILD = _ro(np.arange(1, 17))
BONE_PARENT = _ro(PARENTS[1:].copy())
BONES: tuple[tuple[str, str], ...] = tuple(
    (JOINTS[p], JOINTS[c]) for p, c in zip(BONE_PARENT, BONE_CHILD, strict=True)
)
BONE_NAMES: tuple[str, ...] = tuple(f"{p}->{c}" for p, c in BONES)
#: What a coach calls each bone, in BONE_NAMES order: the words every page, report and export
#: shows (the identifiers above stay the data contract's keys).
BONE_LABELS: tuple[str, ...] = (
    "left pelvis", "left thigh", "left shin", "right pelvis", "right thigh", "right shin",
    "lower spine", "upper spine", "left collarbone", "left upper arm", "left forearm",
    "right collarbone", "right upper arm", "right forearm", "neck", "head",
)  # fmt: skip
#: What a coach calls the angle between each bone and the bone before it (the bend at its
#: parent joint), in BONE_NAMES order; None for the three bones that leave the root.
BEND_LABELS: tuple[str | None, ...] = (
    None, "left hip", "left knee", None, "right hip", "right knee", None, "lower back",
    "left shoulder girdle", "left shoulder", "left elbow", "right shoulder girdle",
    "right shoulder", "right elbow", "upper back", "neck",
)  # fmt: skip

#: The 12 rigid parts (thesis 2.1.1 item 1): all bones leaving one joint form one part.
PARTS: tuple[str, ...] = (
    "abdomen", "lower_chest", "upper_chest", "head", "l_upper_arm", "l_lower_arm",
    "r_upper_arm", "r_lower_arm", "l_upper_leg", "l_lower_leg", "r_upper_leg", "r_lower_leg",
)  # fmt: skip
PART_INDEX: dict[str, int] = {name: i for i, name in enumerate(PARTS)}
#: Part that owns each bone, shape (16,).
BONE_PART = _ro(np.array([0, 8, 9, 0, 10, 11, 0, 1, 2, 4, 5, 2, 6, 7, 2, 3]))
#: Joint a part rotates about (its local origin, thesis 2.1.1 item 2), shape (12,).
PART_ROOT_JOINT = _ro(np.array([0, 7, 8, 15, 9, 10, 12, 13, 1, 2, 4, 5]))
#: Parent part of each part in the part tree, shape (12,); -1 for the abdomen.
PART_PARENT = _ro(np.array([-1, 0, 1, 2, 2, 4, 2, 6, 0, 8, 0, 10]))
#: Bones of each part.
PART_BONES: tuple[tuple[int, ...], ...] = tuple(
    tuple(int(b) for b in np.flatnonzero(BONE_PART == p)) for p in range(N_PARTS)
)

#: Left/right mirror of each joint, shape (17,): used for symmetry and mirrored views.
MIRROR_JOINT = _ro(np.array([0, 4, 5, 6, 1, 2, 3, 7, 8, 12, 13, 14, 9, 10, 11, 15, 16]))

# Joint-angle limits (appendix A, table A.1): the angle at ``joint`` between the bone towards
# ``towards_parent`` and the bone towards ``towards_child`` must lie in [min_deg, 180].
# Where a joint has several child bones (upper chest) the spine continuation (neck) is used,
# since the table describes the bend between the two chest parts.
JOINT_LIMITS: tuple[tuple[str, str, str, float], ...] = (
    ("l_hip", "hip", "l_knee", 20.0),
    ("l_knee", "l_hip", "l_ankle", 35.0),
    ("r_hip", "hip", "r_knee", 20.0),
    ("r_knee", "r_hip", "r_ankle", 35.0),
    ("lower_chest", "hip", "upper_chest", 120.0),
    ("upper_chest", "lower_chest", "neck", 135.0),
    ("l_shoulder", "upper_chest", "l_elbow", 0.0),
    ("l_elbow", "l_shoulder", "l_wrist", 40.0),
    ("r_shoulder", "upper_chest", "r_elbow", 0.0),
    ("r_elbow", "r_shoulder", "r_wrist", 40.0),
    ("neck", "upper_chest", "head_top", 100.0),
)
LIMIT_JOINT = _ro(np.array([JOINT_INDEX[j] for j, _, _, _ in JOINT_LIMITS]))
LIMIT_A = _ro(np.array([JOINT_INDEX[a] for _, a, _, _ in JOINT_LIMITS]))
LIMIT_B = _ro(np.array([JOINT_INDEX[b] for _, _, b, _ in JOINT_LIMITS]))
LIMIT_MIN_RAD = _ro(np.radians([m for _, _, _, m in JOINT_LIMITS]))


def bone_label(name: str) -> str:
    """The coach's word for a bone given as ``"parent->child"`` or by its child joint (as
    domain files may), or ``name`` itself when it is neither."""
    if name in BONE_NAMES:
        return BONE_LABELS[BONE_NAMES.index(name)]
    j = JOINT_INDEX.get(name, 0)
    return BONE_LABELS[j - 1] if j > 0 else name


def column_name(label: str) -> str:
    """A label as a CSV column word: ``"left upper arm"`` -> ``"left_upper_arm"``."""
    return label.replace(" ", "_")
