"""Name tables that map BVH skeletons onto the 17-joint body (DESIGN.md "Skeleton").

Source names are compared after :func:`normalise_name`: the namespace before ``:`` is dropped
(``mixamorig:Hips``), a 3ds Max ``Bip01``/``Bip001`` prefix is dropped, everything is lower
case without spaces, underscores or dots, and a leading ``left``/``right`` becomes ``l``/``r``
(so ``LeftUpLeg``, ``Left_UpLeg`` and ``L UpLeg`` all read ``lupleg``). Tables are written for
the left side with ``{s}`` for the side letter; the right side is derived.

End sites are named ``<parent>/End`` by the parser, so CMU's head top reads ``headend``.
"""

from __future__ import annotations

import re

from engine.body.skeleton import JOINTS

# Order in which our joints are resolved: the upper chest before the lower chest, so that a
# skeleton with only two spine joints gives the upper one to the upper chest (see _resolve).
RESOLVE_ORDER: tuple[str, ...] = (
    "hip", "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle", "upper_chest",
    "lower_chest", "l_shoulder", "l_elbow", "l_wrist", "r_shoulder", "r_elbow", "r_wrist",
    "neck", "head_top",
)  # fmt: skip

_SIDED = ("hip", "knee", "ankle", "shoulder", "elbow", "wrist")

# One table per skeleton family: our joint (left side for sided joints, without the ``l_``)
# -> candidate normalised source names in priority order.
_PROFILES: dict[str, dict[str, tuple[str, ...]]] = {
    # this project's own export (write_bvh): our names
    "coach": {
        "hip": ("hip",),
        "hip_s": ("{s}hip",),
        "knee": ("{s}knee",),
        "ankle": ("{s}ankle",),
        "lower_chest": ("lowerchest",),
        "upper_chest": ("upperchest",),
        "shoulder": ("{s}shoulder",),
        "elbow": ("{s}elbow",),
        "wrist": ("{s}wrist",),
        "neck": ("neck",),
        "head_top": ("headtop",),
    },
    # CMU (Hahne's cgspeed conversion): DESIGN.md's table
    "cmu": {
        "hip": ("hips",),
        "hip_s": ("{s}upleg",),
        "knee": ("{s}leg",),
        "ankle": ("{s}foot",),
        "lower_chest": ("spine",),
        "upper_chest": ("spine1",),
        "shoulder": ("{s}arm",),
        "elbow": ("{s}forearm",),
        "wrist": ("{s}hand",),
        "neck": ("neck1",),
        "head_top": ("headend",),
    },
    # Mixamo: Hips > Spine > Spine1 > Spine2 (shoulders) > Neck > Head > HeadTop_End
    "mixamo": {
        "hip": ("hips",),
        "hip_s": ("{s}upleg",),
        "knee": ("{s}leg",),
        "ankle": ("{s}foot",),
        "lower_chest": ("spine1", "spine"),
        "upper_chest": ("spine2", "spine1"),
        "shoulder": ("{s}arm",),
        "elbow": ("{s}forearm",),
        "wrist": ("{s}hand",),
        "neck": ("neck",),
        "head_top": ("headtopend", "headtop", "headend"),
    },
    # 3ds Max Biped: Bip01 Pelvis, Bip01 L Thigh, ... Bip01 Head, Bip01 HeadNub
    "biped": {
        "hip": ("pelvis", ""),
        "hip_s": ("{s}thigh",),
        "knee": ("{s}calf",),
        "ankle": ("{s}foot",),
        "lower_chest": ("spine1", "spine"),
        "upper_chest": ("spine2", "spine1"),
        "shoulder": ("{s}upperarm",),
        "elbow": ("{s}forearm",),
        "wrist": ("{s}hand",),
        "neck": ("neck",),
        "head_top": ("headnub", "headend", "headnubend"),
    },
    # generic names (lower case exports, MotionBuilder-like, anatomical)
    "generic": {
        "hip": ("hips", "hip", "pelvis", "root"),
        "hip_s": ("{s}hip", "{s}upleg", "{s}thigh", "{s}upperleg", "{s}femur"),
        "knee": ("{s}knee", "{s}leg", "{s}lowerleg", "{s}shin", "{s}calf", "{s}tibia"),
        "ankle": ("{s}ankle", "{s}foot"),
        "lower_chest": ("lowerchest", "spine", "spine1", "abdomen", "lowerback"),
        "upper_chest": ("upperchest", "chest", "spine2", "spine1", "thorax", "upperback"),
        "shoulder": ("{s}shoulder", "{s}arm", "{s}upperarm", "{s}humerus"),
        "elbow": ("{s}elbow", "{s}forearm", "{s}lowerarm", "{s}radius"),
        "wrist": ("{s}wrist", "{s}hand"),
        "neck": ("neck", "neck1"),
        "head_top": ("headtop", "headend", "headtopend", "headnub", "headsite", "headend1"),
    },
}


def normalise_name(name: str) -> str:
    """Canonical form of a source joint name used for table look-ups (see module doc)."""
    n = name.split(":")[-1]
    n = re.sub(r"[^0-9a-z]", "", n.lower())
    n = re.sub(r"^bip0*1", "", n)
    n = re.sub(r"^left", "l", n)
    n = re.sub(r"^right", "r", n)
    return n


def _candidates(profile: dict[str, tuple[str, ...]], joint: str) -> tuple[str, ...]:
    if joint[:2] in ("l_", "r_") and joint[2:] in _SIDED:
        key = "hip_s" if joint[2:] == "hip" else joint[2:]
        return tuple(c.format(s=joint[0]) for c in profile[key])
    return profile[joint]


def resolve(source_names: tuple[str, ...]) -> tuple[dict[str, int], tuple[str, ...], str]:
    """Map source joints onto our 17 joints with the first profile that covers all of them.

    Parameters
    ----------
    source_names : tuple of str
        Names of the BVH's joints and end sites, in file order.

    Returns
    -------
    found : dict of str to int
        Our joint name -> index into ``source_names`` (complete when a profile matched,
        else the best partial match).
    missing : tuple of str
        Our joints that could not be mapped (empty on success).
    profile : str
        Name of the profile used (or the best partial one).
    """
    index: dict[str, int] = {}
    for i, name in enumerate(source_names):
        index.setdefault(normalise_name(name), i)
    best: tuple[dict[str, int], tuple[str, ...], str] | None = None
    for pname, profile in _PROFILES.items():
        found: dict[str, int] = {}
        used: set[int] = set()
        for joint in RESOLVE_ORDER:
            for cand in _candidates(profile, joint):
                k = index.get(cand)
                if k is not None and k not in used:
                    found[joint] = k
                    used.add(k)
                    break
        missing = tuple(j for j in JOINTS if j not in found)
        if not missing:
            return found, (), pname
        if best is None or len(missing) < len(best[1]):
            best = (found, missing, pname)
    assert best is not None
    return best
