"""BVH motion files: import onto the 17-joint body, export, resampling (thesis 2.1.1).

A BVH file holds a joint hierarchy (offsets in the parent's frame, channel lists) and one line
of channel values per frame. :func:`read_bvh` parses it into a :class:`BvhFile`;
:func:`load_reference` runs forward kinematics over all frames at once, maps the source joints
onto the 17 joints of DESIGN.md (name tables in :mod:`engine.io._bvh_names`, or a mapping
given by the user), converts to metres and rotates the world about y so that the body faces +z
at frame 0 (DESIGN.md "Frames of reference"). :func:`write_bvh` exports postures of the
17-joint body so that :func:`load_reference` gives them back.

    parse       read_bvh, parse_bvh: the file's hierarchy and motion, file units (BvhFile);
                BvhLimits refuse untrusted files over a size while they are read
    kinematics  the file's local transforms and forward kinematics over all frames
    load        load_reference: mapping onto the 17-joint body, units, heading, T-pose
    sampling    fractional frames and other frame rates (sample_at, sample_reference, ...)
    write       write_bvh

Conventions
-----------
- Rotation channels are applied in the order listed: ``Zrotation Yrotation Xrotation`` means
  ``R_parent_joint = Rz @ Ry @ Rx`` (degrees). Position channels are added to the joint's
  OFFSET (CMU roots have a zero offset, so either common reading gives the same result).
- A joint's world position is ``p_parent + R_world_parent @ (offset + translation)``.
- End sites are named ``<parent>/End`` (``<parent>/End2`` ... when a joint has several).
- Units: ``units_to_m`` converts file units to metres. When omitted it is guessed from the
  length of the mapped chain ankle-knee-hip-pelvis-chest-neck-head top in the rest pose
  (all rotations zero), which is about 1.5 body heights units for a person:
  0.4-3 -> metres (1.0), 12-45 -> CMU units (0.056444), 45-300 -> centimetres (0.01),
  450-3000 -> millimetres (0.001); anything else must be given explicitly.
- Frame numbers always count the frames of the file as given; a conversion T-pose at frame 0
  is detected and reported as ``Motion.first_motion_frame = 1``, never removed.
"""

from engine.io.bvh.kinematics import bvh_forward_kinematics, local_transforms
from engine.io.bvh.load import (
    CMU_UNITS_TO_M,
    Reference,
    heading_rotation,
    is_tpose,
    load_reference,
)
from engine.io.bvh.parse import BvhFile, BvhLimits, parse_bvh, read_bvh
from engine.io.bvh.sampling import resample, resample_reference, sample_at, sample_reference
from engine.io.bvh.write import write_bvh

__all__ = [
    "CMU_UNITS_TO_M",
    "BvhFile",
    "BvhLimits",
    "Reference",
    "bvh_forward_kinematics",
    "heading_rotation",
    "is_tpose",
    "load_reference",
    "local_transforms",
    "parse_bvh",
    "read_bvh",
    "resample",
    "resample_reference",
    "sample_at",
    "sample_reference",
    "write_bvh",
]
