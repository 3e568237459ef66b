"""BVH motion files: import onto the 17-joint body, export, resampling (thesis 2.1.1).

A BVH file holds a joint hierarchy (offsets in the parent's frame, channel lists) and one line
of channel values per frame. :func:`read_bvh` parses it into a :class:`BvhFile`;
:func:`load_reference` runs forward kinematics over all frames at once, maps the source joints
onto the 17 joints of DESIGN.md (name tables in :mod:`engine.io._bvh_names`, or a mapping
given by the user), converts to metres and rotates the world about y so that the body faces +z
at frame 0 (DESIGN.md "Frames of reference"). :func:`write_bvh` exports postures of the
17-joint body so that :func:`load_reference` gives them back.

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

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from engine.body.kinematics import (
    bone_directions,
    forward_kinematics,
    part_rotations,
    rot_y,
)
from engine.body.shapes import BodyShape
from engine.body.skeleton import JOINT_INDEX, JOINTS, PARENTS, PART_ROOT_JOINT
from engine.errors import InvalidInput
from engine.io._bvh_names import resolve
from engine.types import Motion

CMU_UNITS_TO_M = 0.056444
_CHANNELS = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
_AXIS = {"X": 0, "Y": 1, "Z": 2}


@dataclass(frozen=True)
class BvhFile:
    """A parsed BVH file, in file units, before any mapping.

    Attributes
    ----------
    names : tuple of str
        Joint names in file order (depth first), end sites named ``<parent>/End``. N nodes.
    parents : ndarray of int, shape (N,)
        Parent node of each node, -1 for the root; parents come before children.
    offsets : ndarray, shape (N, 3)
        OFFSET of each node in its parent's frame, file units.
    channels : tuple of tuple of str
        Channel names of each node (empty for end sites).
    is_end_site : ndarray of bool, shape (N,)
    frame_time : float
        Seconds per frame.
    values : ndarray, shape (T, C)
        Channel values per frame, in channel order of the hierarchy; degrees and file units.
    """

    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    is_end_site: np.ndarray
    frame_time: float
    values: np.ndarray

    @property
    def frames(self) -> int:
        return int(self.values.shape[0])

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    def channel_slices(self) -> list[slice]:
        """Column range of each node's channels in :attr:`values`."""
        out, start = [], 0
        for ch in self.channels:
            out.append(slice(start, start + len(ch)))
            start += len(ch)
        return out


@dataclass(frozen=True)
class Reference:
    """A reference motion loaded from BVH, on the 17-joint body (thesis 2.1.1: M and H).

    Attributes
    ----------
    motion : Motion
        Joints (T, 17, 3) in the world frame of DESIGN.md: metres, y up, heading-normalised.
    shape : BodyShape
        The expert's body, :meth:`BodyShape.from_rest_joints` of the T-pose frame when the
        file has one, else of frame 0.
    source_joint_names : tuple of str
        Source node mapped to each of the 17 joints, in :data:`JOINTS` order.
    R_world_bvh : ndarray, shape (3, 3)
        Heading rotation applied (about y): world = R_world_bvh @ (units_to_m * bvh).
    units_to_m : float
        Scale from file units to metres that was used.
    profile : str
        Name table that matched ("cmu", "mixamo", "biped", "generic", "coach", "user").
    bvh : BvhFile
        The raw parsed file (for sampling local rotations, :func:`sample_reference`).
    """

    motion: Motion
    shape: BodyShape
    source_joint_names: tuple[str, ...]
    R_world_bvh: np.ndarray
    units_to_m: float
    profile: str
    bvh: BvhFile

    @property
    def heading_rad(self) -> float:
        """Angle of the heading rotation about y, radians."""
        return float(math.atan2(self.R_world_bvh[0, 2], self.R_world_bvh[0, 0]))

    @property
    def has_tpose(self) -> bool:
        return self.motion.first_motion_frame > 0


# --------------------------------------------------------------------------- parsing


def read_bvh(path: str | os.PathLike) -> BvhFile:
    """Parse a BVH file (text, LF or CRLF).

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    BvhFile

    Raises
    ------
    InvalidInput
        When the file is missing, unreadable or malformed; the message names the line.
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise InvalidInput(f"cannot read BVH file {p}: {exc.strerror or exc}") from None
    text = raw.decode("utf-8", errors="replace")
    return parse_bvh(text, name=p.name)


def parse_bvh(text: str, *, name: str = "<string>") -> BvhFile:
    """Parse the text of a BVH file; see :func:`read_bvh`."""
    lines = text.splitlines()
    first = next((i for i, line in enumerate(lines) if line.strip()), None)
    if first is None or lines[first].strip().upper() != "HIERARCHY":
        raise InvalidInput(f"{name} is not a BVH file (it must start with HIERARCHY)")
    motion_line, hierarchy = _parse_hierarchy(lines, first + 1, name)
    frame_time, values = _parse_motion(lines, motion_line, hierarchy[3], name)
    names, parents, offsets, channels, ends = hierarchy
    return BvhFile(
        names=tuple(names),
        parents=np.array(parents, dtype=int),
        offsets=np.array(offsets, dtype=float).reshape(-1, 3),
        channels=tuple(tuple(c) for c in channels),
        is_end_site=np.array(ends, dtype=bool),
        frame_time=frame_time,
        values=values,
    )


def _err(name: str, line: int, msg: str) -> InvalidInput:
    return InvalidInput(f"{name}, line {line + 1}: {msg}")


def _floats(tokens: list[str], name: str, line: int, what: str) -> list[float]:
    try:
        out = [float(t) for t in tokens]
    except ValueError:
        raise _err(name, line, f"{what} must be numbers, got {' '.join(tokens)!r}") from None
    if not all(math.isfinite(v) for v in out):
        raise _err(name, line, f"{what} must be finite, got {' '.join(tokens)!r}")
    return out


#: What :func:`_parse_hierarchy` reads, per node in file order (N nodes): names, parents,
#: offsets (N, 3) in file units, channel names and end-site flags.
_Hierarchy = tuple[list[str], list[int], list[list[float]], list[list[str]], list[bool]]


@dataclass
class _HierarchyReader:
    """The HIERARCHY section read so far, one line at a time (mutable while parsing).

    Nodes are appended in file order (depth first). ``stack`` holds the nodes whose braces
    are open; ``pending`` is a node just declared whose ``{`` has not come yet.
    """

    name: str
    names: list[str] = field(default_factory=list)
    parents: list[int] = field(default_factory=list)
    offsets: list[list[float]] = field(default_factory=list)
    channels: list[list[str]] = field(default_factory=list)
    ends: list[bool] = field(default_factory=list)
    has_offset: list[bool] = field(default_factory=list)
    stack: list[int] = field(default_factory=list)
    pending: int | None = None

    def read(self, key: str, tokens: list[str], line: str, i: int, opens: bool) -> None:
        """One non-empty line ``i`` (its trailing ``{`` removed, ``opens`` says there was one)."""
        if key in ("ROOT", "JOINT") or (key == "END" and len(tokens) > 1):
            self._node(key, tokens, line, i, opens)
        elif key == "{":
            if self.pending is None:
                raise _err(self.name, i, "'{' without a joint")
            self.stack.append(self.pending)
            self.pending = None
        elif key == "}":
            if not self.stack:
                raise _err(self.name, i, "unmatched '}'")
            self.stack.pop()
        elif key == "OFFSET":
            self._offset(tokens, i)
        elif key == "CHANNELS":
            self._channels(tokens, i)
        else:
            raise _err(self.name, i, f"unexpected {tokens[0]!r} in the HIERARCHY section")

    def finish(self, i: int) -> _Hierarchy:
        """The hierarchy at the MOTION line ``i``, once every brace is closed."""
        if self.stack or self.pending is not None:
            raise _err(self.name, i, "MOTION before the hierarchy's braces are closed")
        if not self.names:
            raise _err(self.name, i, "the hierarchy has no ROOT joint")
        for n, ok in zip(self.names, self.has_offset, strict=True):
            if not ok:
                raise InvalidInput(f"{self.name}: joint {n!r} has no OFFSET")
        return self.names, self.parents, self.offsets, self.channels, self.ends

    def _node(self, key: str, tokens: list[str], line: str, i: int, opens: bool) -> None:
        """A ROOT, JOINT or End Site line: a new node under the innermost open one."""
        self._check_parent(key, tokens[0], i)
        parent = self.stack[-1] if self.stack else -1
        jname = self._end_name(parent) if key == "END" else _joint_name(tokens, line)
        if not jname:
            raise _err(self.name, i, f"{tokens[0]} without a name")
        self.names.append(jname)
        self.parents.append(parent)
        self.offsets.append([0.0, 0.0, 0.0])
        self.channels.append([])
        self.ends.append(key == "END")
        self.has_offset.append(False)
        self.pending = len(self.names) - 1
        if opens:
            self.stack.append(self.pending)
            self.pending = None

    def _check_parent(self, key: str, word: str, i: int) -> None:
        """One ROOT at the top level; every other node inside a joint that is no End Site."""
        if key == "ROOT":
            if self.stack or self.names:
                raise _err(self.name, i, "only one ROOT is supported, at the top level")
        elif not self.stack:
            raise _err(self.name, i, f"{word} outside of a ROOT")
        elif self.ends[self.stack[-1]]:
            raise _err(self.name, i, "an End Site cannot have children")

    def _end_name(self, parent: int) -> str:
        """``<parent>/End``, then ``<parent>/End2`` ... for a joint's further end sites."""
        base = f"{self.names[parent]}/End"
        k = sum(1 for n in self.names if n.startswith(base))
        return base if k == 0 else f"{base}{k + 1}"

    def _offset(self, tokens: list[str], i: int) -> None:
        """``OFFSET x y z`` of the innermost open node, file units."""
        if not self.stack:
            raise _err(self.name, i, "OFFSET outside of a joint")
        if len(tokens) != 4:
            raise _err(self.name, i, f"OFFSET needs 3 numbers, got {len(tokens) - 1}")
        self.offsets[self.stack[-1]] = _floats(tokens[1:], self.name, i, "OFFSET values")
        self.has_offset[self.stack[-1]] = True

    def _channels(self, tokens: list[str], i: int) -> None:
        """``CHANNELS n name ...`` of the innermost open joint (an End Site has none)."""
        if not self.stack or self.ends[self.stack[-1]]:
            raise _err(self.name, i, "CHANNELS outside of a joint")
        try:
            n_chans = int(tokens[1])
        except (IndexError, ValueError):
            raise _err(self.name, i, "CHANNELS needs a count") from None
        chans = tokens[2:]
        if n_chans != len(chans):
            raise _err(self.name, i, f"CHANNELS says {n_chans} channels but lists {len(chans)}")
        # channel names are matched case-insensitively and stored in their canonical spelling
        canon = {c.lower(): c for c in _CHANNELS}
        bad = [c for c in chans if c.lower() not in canon]
        if bad:
            raise _err(self.name, i, f"unknown channel {bad[0]!r}")
        self.channels[self.stack[-1]] = [canon[c.lower()] for c in chans]


def _joint_name(tokens: list[str], line: str) -> str:
    """The name after ROOT or JOINT (it may contain spaces); "" when there is none."""
    return line.split(None, 1)[1].strip() if len(tokens) > 1 else ""


def _parse_hierarchy(lines: list[str], start: int, name: str) -> tuple[int, _Hierarchy]:
    """Read the HIERARCHY section from line ``start`` up to the MOTION line.

    Returns the MOTION line's index and the nodes (:data:`_Hierarchy`); raises
    :class:`InvalidInput` naming the line of the first problem.
    """
    reader = _HierarchyReader(name)
    for i in range(start, len(lines)):
        line = lines[i].strip()
        if not line:
            continue
        opens = line.endswith("{") and line != "{"  # "JOINT name {" on one line
        if opens:
            line = line[:-1].strip()
        tokens = line.split()
        key = tokens[0].upper()
        if key == "MOTION":
            return i, reader.finish(i)
        if reader.pending is not None and key != "{":
            raise _err(
                name, i, f"expected '{{' after {reader.names[reader.pending]!r}, got {line!r}"
            )
        reader.read(key, tokens, line, i, opens)
    raise InvalidInput(f"{name}: no MOTION section (the file ends inside the hierarchy)")


def _parse_motion(lines: list[str], at: int, channels: list[list[str]], name: str):
    n_ch = sum(len(c) for c in channels)
    i = at + 1

    def header(key: str) -> tuple[int, str]:
        nonlocal i
        while i < len(lines) and not lines[i].strip():
            i += 1
        if i >= len(lines):
            raise InvalidInput(f"{name}: the MOTION section ends before '{key}'")
        line = lines[i].strip()
        if not line.lower().startswith(key.lower()):
            raise _err(name, i, f"expected '{key}', got {line[:40]!r}")
        i += 1
        return i - 1, line[len(key) :].strip()

    ln, frames_s = header("Frames:")
    try:
        n_frames = int(frames_s)
    except ValueError:
        raise _err(name, ln, f"Frames must be an integer, got {frames_s!r}") from None
    if n_frames <= 0:
        raise _err(name, ln, f"the file has {n_frames} frames; at least one is needed")
    ln, ft_s = header("Frame Time:")
    (frame_time,) = _floats([ft_s], name, ln, "Frame Time")
    if frame_time <= 0:
        raise _err(name, ln, f"Frame Time must be positive, got {frame_time}")
    rows = [(k, lines[k]) for k in range(i, len(lines)) if lines[k].strip()]
    if len(rows) < n_frames:
        raise InvalidInput(
            f"{name}: truncated file: the header announces {n_frames} frames, "
            f"only {len(rows)} frame lines follow"
        )
    values = np.empty((n_frames, n_ch))
    for f, (k, line) in enumerate(rows[:n_frames]):
        tokens = line.split()
        if len(tokens) != n_ch:
            raise _err(
                name, k, f"frame {f} has {len(tokens)} values, the hierarchy has {n_ch} channels"
            )
        try:
            values[f] = np.array(tokens, dtype=float)
        except ValueError:
            bad = next(t for t in tokens if not _is_number(t))
            raise _err(name, k, f"frame {f}: {bad!r} is not a number") from None
    if not np.all(np.isfinite(values)):
        f = int(np.flatnonzero(~np.all(np.isfinite(values), axis=1))[0])
        raise _err(name, rows[f][0], f"frame {f} contains NaN or infinite values")
    return frame_time, values


def _is_number(t: str) -> bool:
    try:
        float(t)
    except ValueError:
        return False
    return True


# --------------------------------------------------------------------------- kinematics


def _axis_rotations(axis: int, deg: np.ndarray) -> np.ndarray:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[..., axis, axis] = 1.0
    R[..., i, i], R[..., i, j] = c, -s
    R[..., j, i], R[..., j, j] = s, c
    return R


def local_transforms(bvh: BvhFile) -> tuple[np.ndarray, np.ndarray]:
    """Local rotation and translation of every node in every frame.

    Returns
    -------
    R_parent_node : ndarray, shape (T, N, 3, 3)
    t_parent_node : ndarray, shape (T, N, 3)
        Offset plus position channels, file units.
    """
    T, N = bvh.frames, len(bvh.names)
    R = np.broadcast_to(np.eye(3), (T, N, 3, 3)).copy()
    t = np.broadcast_to(bvh.offsets, (T, N, 3)).copy()
    for n, (sl, chans) in enumerate(zip(bvh.channel_slices(), bvh.channels, strict=True)):
        for c, ch in zip(range(sl.start, sl.stop), chans, strict=True):
            axis = _AXIS[ch[0]]
            if ch.endswith("position"):
                t[:, n, axis] += bvh.values[:, c]
            else:
                R[:, n] = R[:, n] @ _axis_rotations(axis, bvh.values[:, c])
    return R, t


def bvh_forward_kinematics(
    bvh: BvhFile, R_local: np.ndarray | None = None, t_local: np.ndarray | None = None
) -> np.ndarray:
    """World positions of every node of a BVH in every frame (file units, file frame).

    Parameters
    ----------
    bvh : BvhFile
    R_local, t_local : ndarray, shape (T, N, 3, 3) and (T, N, 3), optional
        Local transforms (e.g. interpolated ones); from the file's channels when omitted.

    Returns
    -------
    positions : ndarray, shape (T, N, 3)
    """
    if R_local is None or t_local is None:
        R_local, t_local = local_transforms(bvh)
    T, N = R_local.shape[:2]
    R_world = np.empty((T, N, 3, 3))
    pos = np.empty((T, N, 3))
    for n, p in enumerate(bvh.parents):
        if p < 0:
            R_world[:, n] = R_local[:, n]
            pos[:, n] = t_local[:, n]
        else:
            R_world[:, n] = R_world[:, p] @ R_local[:, n]
            pos[:, n] = pos[:, p] + np.einsum("tij,tj->ti", R_world[:, p], t_local[:, n])
    return pos


# --------------------------------------------------------------------------- import


def load_reference(
    path: str | os.PathLike,
    *,
    mapping: dict[str, str] | None = None,
    units_to_m: float | None = None,
    normalise_heading: bool = True,
) -> Reference:
    """Load a BVH reference motion onto the 17-joint body (thesis 2.1.1).

    Parameters
    ----------
    path : str or path-like
        The BVH file.
    mapping : dict of str to str, optional
        Our joint name -> source joint name (end sites are ``<parent>/End``), overriding
        the name tables for the joints it names.
    units_to_m : float, optional
        Metres per file unit; guessed from the skeleton's size when omitted (module doc).
    normalise_heading : bool
        Rotate about y (through the origin) so that the body faces +z at frame 0
        (DESIGN.md "Frames of reference"). True for every analysis; False keeps the
        file's own heading.

    Returns
    -------
    Reference

    Raises
    ------
    InvalidInput
        Malformed file, unknown names in ``mapping``, joints that cannot be mapped (the
        message names them), or units that cannot be guessed.
    """
    bvh = read_bvh(path)
    idx, profile = _mapping(bvh, mapping)
    if units_to_m is None:
        units_to_m = _guess_units(bvh, idx, Path(path).name)
    elif not (isinstance(units_to_m, int | float) and math.isfinite(units_to_m) and units_to_m > 0):
        raise InvalidInput(f"units_to_m must be a positive number, got {units_to_m!r}")
    joints = bvh_forward_kinematics(bvh)[:, idx] * float(units_to_m)
    R = heading_rotation(joints[0]) if normalise_heading else np.eye(3)
    joints = joints @ R.T
    first = 1 if is_tpose(joints[0]) and bvh.frames > 1 else 0
    shape = BodyShape.from_rest_joints(joints[0])
    motion = Motion(joints=joints, fps=bvh.fps, name=Path(path).stem, first_motion_frame=first)
    return Reference(
        motion=motion,
        shape=shape,
        source_joint_names=tuple(bvh.names[i] for i in idx),
        R_world_bvh=R,
        units_to_m=float(units_to_m),
        profile=profile,
        bvh=bvh,
    )


def _mapping(bvh: BvhFile, mapping: dict[str, str] | None) -> tuple[np.ndarray, str]:
    found, missing, profile = resolve(bvh.names)
    if mapping:
        unknown = [k for k in mapping if k not in JOINT_INDEX]
        if unknown:
            raise InvalidInput(
                f"mapping names unknown joints {unknown}; our joints are {list(JOINTS)}"
            )
        pos = {n: i for i, n in enumerate(bvh.names)}
        absent = [v for v in mapping.values() if v not in pos]
        if absent:
            raise InvalidInput(f"mapping refers to joints not in the file: {absent}")
        found = dict(found) | {k: pos[v] for k, v in mapping.items()}
        missing = tuple(j for j in JOINTS if j not in found)
        profile = "user" if not missing else profile
    if missing:
        raise InvalidInput(
            "cannot map the BVH skeleton onto the 17-joint body: missing "
            + ", ".join(missing)
            + f" (closest name table: {profile}; the file's joints are "
            + ", ".join(bvh.names)
            + "). Pass a mapping {our_joint: file_joint} for the missing joints."
        )
    return np.array([found[j] for j in JOINTS]), profile


_UNIT_RANGES = (
    (0.4, 3.0, 1.0),
    (12.0, 45.0, CMU_UNITS_TO_M),
    (45.0, 300.0, 0.01),
    (450, 3000, 0.001),
)
_CHAIN = ("l_ankle", "l_knee", "l_hip", "hip", "lower_chest", "upper_chest", "neck", "head_top")


def _guess_units(bvh: BvhFile, idx: np.ndarray, name: str) -> float:
    rest = np.zeros((len(bvh.names), 3))
    for n, p in enumerate(bvh.parents):
        rest[n] = bvh.offsets[n] + (rest[p] if p >= 0 else 0.0)
    pts = rest[idx[[JOINT_INDEX[j] for j in _CHAIN]]]
    length = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
    for lo, hi, k in _UNIT_RANGES:
        if lo <= length < hi:
            return k
    raise InvalidInput(
        f"{name}: cannot guess the units (ankle-to-head chain is {length:.4g} file units); "
        "pass units_to_m"
    )


def heading_rotation(joints0: np.ndarray) -> np.ndarray:
    """Rotation about y that turns a posture to face +z (DESIGN.md "Frames of reference").

    Facing is the horizontal part of ``cross(l_hip - r_hip, up)``.

    Parameters
    ----------
    joints0 : ndarray, shape (17, 3)

    Returns
    -------
    R : ndarray, shape (3, 3)
        ``R @ facing`` is along +z.
    """
    f = np.cross(joints0[JOINT_INDEX["l_hip"]] - joints0[JOINT_INDEX["r_hip"]], [0.0, 1.0, 0.0])
    if math.hypot(f[0], f[2]) < 1e-9:
        return np.eye(3)
    return rot_y(math.atan2(-f[0], f[2]))


_ARM_BONES = np.array([9, 10, 12, 13])  # upper and lower arms (bone b ends at joint b + 1)
_LEG_BONES = np.array([1, 2, 4, 5])


def is_tpose(joints: np.ndarray, *, tol_deg: float = 20.0) -> bool:
    """Whether a posture is a conversion T-pose: arms straight out sideways, legs straight down.

    Parameters
    ----------
    joints : ndarray, shape (17, 3)
        Heading-normalised (facing +z, left at +x).
    tol_deg : float
        Largest deviation of any arm or leg bone from its T-pose direction.
    """
    d = bone_directions(np.asarray(joints, dtype=float))
    want = np.zeros((8, 3))
    want[:2, 0], want[2:4, 0], want[4:, 1] = 1.0, -1.0, -1.0
    cos = np.sum(d[np.r_[_ARM_BONES, _LEG_BONES]] * want, axis=1)
    return bool(np.all(cos > math.cos(math.radians(tol_deg))))


# --------------------------------------------------------------------------- sampling


def _check_frames(motion: Motion, frames: np.ndarray) -> np.ndarray:
    f = np.asarray(frames, dtype=float)
    if f.ndim != 1 or not np.all(np.isfinite(f)):
        raise InvalidInput(f"frames must be a 1-D array of finite numbers, got shape {f.shape}")
    if f.size and (f.min() < 0 or f.max() > motion.frames - 1):
        raise InvalidInput(
            f"frames must lie in [0, {motion.frames - 1}], got [{f.min():g}, {f.max():g}]"
        )
    return f


def sample_at(motion: Motion, shape: BodyShape, frames: np.ndarray) -> np.ndarray:
    """Postures of a motion at fractional frames (slerp of part rotations, linear root).

    The body is rebuilt with forward kinematics on ``shape`` (thesis 2.1.1: H fixed, B_t
    from p_t and theta_t), so bone lengths are constant; multi-bone parts (abdomen, upper
    chest) become rigid.

    Parameters
    ----------
    motion : Motion
    shape : BodyShape
    frames : ndarray, shape (N,)
        Fractional frame numbers in [0, T - 1].

    Returns
    -------
    joints : ndarray, shape (N, 17, 3)

    Raises
    ------
    InvalidInput
        When ``frames`` is not 1-D, not finite or out of range.
    """
    f = _check_frames(motion, frames)
    return _interpolate(motion.joints, shape, f)


def _interpolate(joints: np.ndarray, shape: BodyShape, f: np.ndarray) -> np.ndarray:
    T = joints.shape[0]
    R = part_rotations(joints, shape.offsets)
    if T == 1:
        Ri = np.broadcast_to(R[0], (f.size,) + R.shape[1:])
        root = np.broadcast_to(joints[0, 0], (f.size, 3))
        return forward_kinematics(shape.offsets, root, Ri)
    times = np.arange(T, dtype=float)
    Ri = np.empty((f.size,) + R.shape[1:])
    for p in range(R.shape[1]):
        Ri[:, p] = Slerp(times, Rotation.from_matrix(R[:, p]))(f).as_matrix()
    root = np.stack([np.interp(f, times, joints[:, 0, k]) for k in range(3)], axis=-1)
    return forward_kinematics(shape.offsets, root, Ri)


def _resample_frames(motion: Motion, fps: float) -> tuple[np.ndarray, int]:
    """Old fractional frames (N,) of the new frames at ``fps``, and the new first motion frame.

    Raises InvalidInput when ``fps`` is not a positive finite number.
    """
    if not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0):
        raise InvalidInput(f"fps must be a positive number, got {fps!r}")
    n = int(math.floor(motion.duration_s * fps + 1e-6)) + 1
    f = np.minimum(np.arange(n) * motion.fps / fps, motion.frames - 1)
    first = int(math.ceil(motion.first_motion_frame * fps / motion.fps - 1e-9))
    return f, first


def resample(motion: Motion, fps: float, shape: BodyShape) -> Motion:
    """The motion at another frame rate (slerp of part rotations, linear root).

    New frame k is at time k / fps, for every such time within the motion, so the first
    frame is kept and the last one too when the duration is a whole number of new frames.

    Parameters
    ----------
    motion : Motion
    fps : float
        New frame rate, frames per second.
    shape : BodyShape
        Body whose bone lengths the resampled postures get.

    Returns
    -------
    Motion
        ``first_motion_frame`` is the first new frame at or after the old one.

    Raises
    ------
    InvalidInput
        When ``fps`` is not a positive finite number.
    """
    f, first = _resample_frames(motion, fps)
    joints = _interpolate(motion.joints, shape, f)
    return Motion(joints=joints, fps=float(fps), name=motion.name, first_motion_frame=first)


def sample_reference(reference: Reference, frames: np.ndarray) -> np.ndarray:
    """The reference at fractional frames by slerp of the file's *local* rotations.

    This is the convention of the benchmark truth files (the source skeleton's own joints
    interpolated, then mapped), unlike :func:`sample_at`, which interpolates on the
    17-joint body.

    Parameters
    ----------
    reference : Reference
    frames : ndarray, shape (N,)
        Fractional frame numbers in [0, T - 1].

    Returns
    -------
    joints : ndarray, shape (N, 17, 3)
        World frame of the reference (metres, heading-normalised).
    """
    f = _check_frames(reference.motion, frames)
    bvh = reference.bvh
    R, t = local_transforms(bvh)
    times = np.arange(bvh.frames, dtype=float)
    N = R.shape[1]
    if bvh.frames == 1:
        Ri, ti = np.broadcast_to(R[:1], (f.size, N, 3, 3)), np.broadcast_to(t[:1], (f.size, N, 3))
    else:
        Ri = np.empty((f.size, N, 3, 3))
        for n in range(N):
            Ri[:, n] = Slerp(times, Rotation.from_matrix(R[:, n]))(f).as_matrix()
        lo = np.clip(np.floor(f).astype(int), 0, bvh.frames - 2)
        w = (f - lo)[:, None, None]
        ti = (1 - w) * t[lo] + w * t[lo + 1]
    idx = np.array([reference.bvh.names.index(n) for n in reference.source_joint_names])
    pos = bvh_forward_kinematics(bvh, Ri, ti)[:, idx] * reference.units_to_m
    return pos @ reference.R_world_bvh.T


def resample_reference(reference: Reference, fps: float) -> Motion:
    """The reference at another frame rate, by slerp of the file's local rotations.

    Like :func:`resample` (same frame times, same ``first_motion_frame`` rule) but with
    the benchmark truth's interpolation (:func:`sample_reference`), so bone directions keep
    the source skeleton's non-rigid spine and shoulders exactly.

    Parameters
    ----------
    reference : Reference
    fps : float
        New frame rate.

    Returns
    -------
    Motion

    Raises
    ------
    InvalidInput
        When ``fps`` is not a positive finite number.
    """
    m = reference.motion
    f, first = _resample_frames(m, fps)
    joints = sample_reference(reference, f)
    return Motion(joints=joints, fps=float(fps), name=m.name, first_motion_frame=first)


# --------------------------------------------------------------------------- export


def write_bvh(
    path: str | os.PathLike,
    joints: np.ndarray,
    fps: float,
    shape: BodyShape | None = None,
) -> Path:
    """Write postures of the 17-joint body as a BVH file (metres, our joint names).

    The hierarchy is the 17-joint skeleton with ``shape.offsets`` as bone offsets (constant
    bone lengths) and zero-rotation default posture; the root (hip) has position channels,
    every joint ``Zrotation Yrotation Xrotation`` (its part's rotation relative to its
    parent part, :func:`engine.body.kinematics.part_rotations`), leaves an End Site at zero
    offset. Postures produced by forward kinematics with ``shape`` are reproduced exactly by
    :func:`load_reference` (to ~1e-9 m); others are fitted part by part. Write already
    heading-normalised postures (or load with ``normalise_heading=False``) for an exact
    round trip.

    Parameters
    ----------
    path : str or path-like
    joints : ndarray, shape (T, 17, 3)
        Metres.
    fps : float
    shape : BodyShape, optional
        Bone offsets of the default posture; ``BodyShape.from_rest_joints(joints[0])``
        when omitted.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    InvalidInput
        When ``joints`` is not (T, 17, 3) finite, or ``fps`` is not positive.
    """
    J = np.asarray(joints, dtype=float)
    if J.ndim != 3 or J.shape[1:] != (17, 3) or J.shape[0] < 1:
        raise InvalidInput(f"joints must have shape (T, 17, 3), got {J.shape}")
    if not np.all(np.isfinite(J)):
        raise InvalidInput("joints contains NaN or infinite values")
    if not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0):
        raise InvalidInput(f"fps must be a positive number, got {fps!r}")
    if shape is None:
        shape = BodyShape.from_rest_joints(J[0])
    R_world = part_rotations(J, shape.offsets)  # (T, 12, 3, 3)
    # world rotation of each BVH joint: that of the part it is the root of; leaves
    # (ankles, wrists, head top) inherit their parent's, i.e. a zero local rotation
    part_of_joint = np.full(17, -1)
    part_of_joint[PART_ROOT_JOINT] = np.arange(len(PART_ROOT_JOINT))
    R_joint = np.empty((J.shape[0], 17, 3, 3))
    for j in range(17):
        R_joint[:, j] = (
            R_world[:, part_of_joint[j]] if part_of_joint[j] >= 0 else R_joint[:, PARENTS[j]]
        )
    R_local = R_joint.copy()
    R_local[:, 1:] = np.swapaxes(R_joint[:, PARENTS[1:]], -1, -2) @ R_joint[:, 1:]
    euler = Rotation.from_matrix(R_local.reshape(-1, 3, 3)).as_euler("ZYX", degrees=True)
    euler = euler.reshape(J.shape[0], 17, 3)

    children: dict[int, list[int]] = {j: [] for j in range(17)}
    for j in range(1, 17):
        children[int(PARENTS[j])].append(j)
    out: list[str] = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        pad = "\t" * depth
        off = np.zeros(3) if j == 0 else shape.offsets[j - 1]
        out.append(f"{pad}{'ROOT' if j == 0 else 'JOINT'} {JOINTS[j]}")
        out.append(f"{pad}{{")
        out.append(f"{pad}\tOFFSET {off[0]:.9f} {off[1]:.9f} {off[2]:.9f}")
        pos = "Xposition Yposition Zposition " if j == 0 else ""
        out.append(f"{pad}\tCHANNELS {6 if j == 0 else 3} {pos}Zrotation Yrotation Xrotation")
        for c in children[j]:
            emit(c, depth + 1)
        if not children[j]:
            out.extend([f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET 0 0 0", f"{pad}\t}}"])
        out.append(f"{pad}}}")

    emit(0, 0)
    order = _dfs_order(children)
    out += ["MOTION", f"Frames: {J.shape[0]}", f"Frame Time: {1.0 / fps:.10g}"]
    cols = np.concatenate([J[:, :1, :], euler[:, order]], axis=1).reshape(J.shape[0], -1)
    out += [" ".join(f"{v:.10g}" for v in row) for row in cols]
    p = Path(path)
    p.write_text("\n".join(out) + "\n")
    return p


def _dfs_order(children: dict[int, list[int]]) -> list[int]:
    order: list[int] = []

    def visit(j: int) -> None:
        order.append(j)
        for c in children[j]:
            visit(c)

    visit(0)
    return order
