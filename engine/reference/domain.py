"""Per-reference domain knowledge (thesis 6.8): a JSON document a coach gives with a reference.

The service stores it with the reference and passes it in every analysis request; the
command line reads it from ``<ref>.domain.json`` beside the BVH (:func:`find_domain`).

A coach states what matters in this motion: segment names, per-bone weights (the torso
matters more than the knees in Taichi) and per-bone tolerances in degrees (a "high" or "low"
stance is both fine). They change the *reported score* only, never the raw errors::

    {
      "version": 1,
      "sport": "golf",
      "segment_names": ["address", "takeaway", "top", "downswing", "impact", "finish"],
      "segments": [1, 60, 130, 170, 190, 215],
      "key_position_names": ["address", "takeaway", "top", "transition", "impact", "finish",
                             "end"],
      "bone_weights": {"hip->lower_chest": 3, "l_elbow": 2},
      "tolerances_deg": {"l_knee": 15, "r_knee": 15},
      "default_tolerance_deg": 0,
      "boundary": {"joints": ["r_wrist"], "direction_change_deg": 120},
      "variation": {"bone_sd_deg": [[2.1, 3.0, ...], ...], "sd_floor_deg": 5, "z_limit": 3,
                    "takes": ["63_01", "63_02"], "median_take": "63_01"}
    }

``segments`` (optional) lists the reference frame each segment starts at (frame numbers count
the file's frames); the last segment ends at the motion's last frame. Without it the
boundaries are detected from the ``boundary`` joints' direction changes (thesis 5.4.2), and
``segment_names`` must then name as many segments as are detected (``coach reference inspect
REF.bvh`` prints them).

``key_position_names`` (optional) names the moments between segments, which a coach reviews
("address", "top", "impact"): one per segment start, then the last segment's end. Without
them they are called after the segments ("start of downswing").

``variation`` (optional, written by ``coach reference build`` from several takes, seed 002)
gives the expert's own spread of every bone at every reference frame (one row of 16 per frame
of the file). An analysis then also reports each error as ``z = error / max(sd, floor)`` and
calls a bone outside the expert's range where z exceeds ``z_limit``.

Bones are named either ``parent->child`` (:data:`engine.body.skeleton.BONE_NAMES`) or by the
joint they end at (``"l_elbow"`` = upper arm ``l_shoulder->l_elbow``). Unnamed bones get weight
1 and ``default_tolerance_deg``.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from engine.body.skeleton import BONE_NAMES, JOINT_INDEX, JOINTS, N_BONES
from engine.errors import InvalidInput
from engine.reference.boundaries import reference_boundaries, segments_from_list
from engine.types import Motion, Segments

GOLF_SEGMENT_NAMES = ("address", "takeaway", "top", "downswing", "impact", "finish")
_KEYS = {
    "version", "sport", "segment_names", "bone_weights", "tolerances_deg",
    "default_tolerance_deg", "boundary", "notes", "segments", "variation",
    "key_position_names",
}  # fmt: skip
_VARIATION_KEYS = {"bone_sd_deg", "sd_floor_deg", "z_limit", "takes", "median_take"}


@dataclass(frozen=True)
class Domain:
    """Domain knowledge of one reference (thesis 6.8).

    Attributes
    ----------
    sport : str
    segment_names : tuple of str
        One per reference segment, or empty to keep the reference's own names.
    segment_starts : tuple of int
        The coach's own segment starts (reference frames), or empty to detect them.
    key_position_names : tuple of str
        The moments at each segment's start and at the last one's end, or empty.
    bone_weights : ndarray, shape (16,)
        Non-negative, at least one positive.
    tolerances : ndarray, shape (16,)
        Radians: an angle up to this is not counted in the score.
    boundary_joints : tuple of str
        Joints whose direction change marks a boundary (empty: stage-4 default).
    direction_change_deg : float or None
        Boundary threshold (thesis 5.4.2: 60 Taichi, 120 golf); None: stage-4 default.
    bone_sd : ndarray, shape (T, 16), or None
        Radians: the expert's spread of each bone at each reference frame (seed 002 eq. 22).
    sd_floor : float
        Radians: the smallest spread a z-score divides by (below it the engine cannot measure).
    z_limit : float
        A bone whose error exceeds this many spreads is outside the expert's range.
    doc : dict or None
        The validated document it was parsed from (:func:`parse_domain`; None for a domain
        built in code): what a stage output stores, so reading it back gives this domain
        exactly.
    """

    sport: str = ""
    segment_names: tuple[str, ...] = ()
    segment_starts: tuple[int, ...] = ()
    key_position_names: tuple[str, ...] = ()
    bone_weights: np.ndarray = field(default_factory=lambda: np.ones(N_BONES))
    tolerances: np.ndarray = field(default_factory=lambda: np.zeros(N_BONES))
    boundary_joints: tuple[str, ...] = ()
    direction_change_deg: float | None = None
    bone_sd: np.ndarray | None = field(default=None, compare=False, repr=False)
    sd_floor: float = float(np.radians(5.0))
    z_limit: float = 3.0
    doc: dict[str, Any] | None = field(default=None, compare=False, repr=False)

    def z_scores(self, bone_errors: np.ndarray, reference_frames: np.ndarray) -> np.ndarray:
        """Errors against the expert's own variation: ``error / max(sd, floor)``.

        Parameters
        ----------
        bone_errors : ndarray, shape (N, 16)
            Radians.
        reference_frames : ndarray, shape (N,)
            The file's reference frame each error was measured at.

        Returns
        -------
        z : ndarray, shape (N, 16)
            Finite, since the floor is positive.
        """
        if self.bone_sd is None:
            raise InvalidInput("this reference has no variation: build it from several takes")
        frames = np.clip(np.asarray(reference_frames, int), 0, len(self.bone_sd) - 1)
        return np.asarray(bone_errors, float) / np.maximum(self.bone_sd[frames], self.sd_floor)

    def score(self, bone_errors: np.ndarray) -> np.ndarray:
        """Domain-specific error: weighted mean of the excess over each bone's tolerance.

        Parameters
        ----------
        bone_errors : ndarray, shape (..., 16)
            Raw per-bone angles, radians.

        Returns
        -------
        score : ndarray, shape (...)
            Radians.
        """
        excess = np.maximum(np.asarray(bone_errors, float) - self.tolerances, 0.0)
        return (excess * self.bone_weights).sum(-1) / self.bone_weights.sum()

    def to_dict(self) -> dict[str, Any]:
        return {
            "sport": self.sport,
            "segment_names": list(self.segment_names),
            "segment_starts": list(self.segment_starts),
            "key_position_names": list(self.key_position_names),
            "bone_weights": [float(w) for w in self.bone_weights],
            "tolerances_deg": [float(t) for t in np.degrees(self.tolerances)],
            "boundary_joints": list(self.boundary_joints),
            "direction_change_deg": self.direction_change_deg,
            **({} if self.bone_sd is None else {"variation": self._variation_summary()}),
        }

    def _variation_summary(self) -> dict[str, Any]:
        v = (self.doc or {}).get("variation", {})
        return {
            "frames": int(len(self.bone_sd)) if self.bone_sd is not None else 0,
            "sd_floor_deg": float(np.degrees(self.sd_floor)), "z_limit": self.z_limit,
            "takes": list(v.get("takes", [])), "median_take": v.get("median_take", ""),
        }  # fmt: skip


def _bone_index(name: str, where: str) -> int:
    if name in BONE_NAMES:
        return BONE_NAMES.index(name)
    if name in JOINT_INDEX and JOINT_INDEX[name] > 0:
        return JOINT_INDEX[name] - 1  # bone b ends at joint b + 1
    raise InvalidInput(
        f"{where}: unknown bone {name!r}; use 'parent->child' ({', '.join(BONE_NAMES[:2])}, ...) "
        f"or the joint the bone ends at ({', '.join(JOINTS[1:4])}, ...)"
    )


def _number(value: Any, where: str, *, minimum: float = 0.0) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
        raise InvalidInput(f"{where}: expected a number, got {value!r}")
    if value < minimum:
        raise InvalidInput(f"{where}: expected a number >= {minimum}, got {value}")
    return float(value)


def _per_bone(doc: Any, where: str, default: float) -> np.ndarray:
    out = np.full(N_BONES, default)
    if doc is None:
        return out
    if not isinstance(doc, dict):
        raise InvalidInput(f"{where}: expected an object mapping bone names to numbers")
    for name, value in doc.items():
        out[_bone_index(str(name), where)] = _number(value, f"{where}.{name}")
    return out


def parse_domain(doc: Any, *, n_segments: int | None = None, source: str = "domain") -> Domain:
    """Validate a parsed domain document (thesis 6.8).

    Parameters
    ----------
    doc : dict
        The JSON content.
    n_segments : int, optional
        Number of detected reference segments; when given and the document sets no
        ``segments`` of its own, ``segment_names`` must match it.
    source : str
        Name used in error messages (the file path).

    Raises
    ------
    InvalidInput
        Naming the offending key.
    """
    if not isinstance(doc, dict):
        raise InvalidInput(f"{source}: expected a JSON object")
    unknown = sorted(set(doc) - _KEYS)
    if unknown:
        raise InvalidInput(f"{source}: unknown keys {unknown}; allowed {sorted(_KEYS)}")
    if doc.get("version", 1) != 1:
        raise InvalidInput(f"{source}.version: expected 1, got {doc.get('version')!r}")
    sport = doc.get("sport", "")
    if not isinstance(sport, str):
        raise InvalidInput(f"{source}.sport: expected a string")
    names, starts = _segments(doc, source, n_segments)
    keys = _key_positions(doc, source, len(starts) or len(names) or n_segments)
    weights, tolerances = _bone_numbers(doc, source)
    joints, change = _boundary(doc.get("boundary", {}), f"{source}.boundary")
    sd, floor, z_limit = _variation(doc.get("variation"), f"{source}.variation")
    return Domain(
        sport=sport, segment_names=names, segment_starts=starts, key_position_names=keys,
        bone_weights=weights,
        tolerances=tolerances, boundary_joints=joints, direction_change_deg=change,
        bone_sd=sd, sd_floor=floor, z_limit=z_limit, doc=dict(doc),
    )  # fmt: skip


def _variation(doc: Any, where: str) -> tuple[np.ndarray | None, float, float]:
    """The expert's spread (T, 16) radians, its floor (radians) and the z limit."""
    floor, z_limit = float(np.radians(5.0)), 3.0
    if doc is None:
        return None, floor, z_limit
    if not isinstance(doc, dict) or set(doc) - _VARIATION_KEYS or "bone_sd_deg" not in doc:
        raise InvalidInput(f"{where}: expected an object with 'bone_sd_deg' and optionally "
                           f"{sorted(_VARIATION_KEYS - {'bone_sd_deg'})}")  # fmt: skip
    try:
        sd = np.asarray(doc["bone_sd_deg"], dtype=float)
    except (TypeError, ValueError):
        sd = np.empty(0)
    if sd.ndim != 2 or sd.shape[1] != N_BONES or len(sd) < 1 or not np.isfinite(sd).all() \
            or (sd < 0).any() or (sd > 180).any():  # fmt: skip
        raise InvalidInput(f"{where}.bone_sd_deg: expected one row of {N_BONES} numbers "
                           "in [0, 180] per reference frame")  # fmt: skip
    floor = np.radians(_number(doc.get("sd_floor_deg", 5.0), f"{where}.sd_floor_deg"))
    if floor <= 0:
        raise InvalidInput(f"{where}.sd_floor_deg: must be positive (z divides by it)")
    z_limit = _number(doc.get("z_limit", 3.0), f"{where}.z_limit")
    return np.radians(sd), float(floor), z_limit


def check_variation(motion: Motion, domain: Domain | None) -> None:
    """A domain's variation must have one row per frame of the reference it describes.

    Raises
    ------
    InvalidInput
        The row count differs: the variation was built for another reference.
    """
    if domain is not None and domain.bone_sd is not None and len(domain.bone_sd) != motion.frames:
        raise InvalidInput(
            f"domain variation: {len(domain.bone_sd)} rows for a reference of {motion.frames} "
            "frames; it was built for another reference"
        )


def _segments(
    doc: dict, source: str, n_segments: int | None
) -> tuple[tuple[str, ...], tuple[int, ...]]:
    """``segment_names`` and ``segments`` (starts), checked against each other and against
    ``n_segments`` detected segments when the document sets no starts."""
    names = doc.get("segment_names", [])
    if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names):
        raise InvalidInput(f"{source}.segment_names: expected a list of non-empty strings")
    starts = doc.get("segments", [])
    if (
        not isinstance(starts, list)
        or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in starts)
        or any(b <= a for a, b in zip(starts, starts[1:], strict=False))
    ):
        raise InvalidInput(
            f"{source}.segments: expected the reference frames where the segments start, "
            f"whole numbers >= 0 in increasing order, got {starts!r}"
        )
    if starts and names and len(names) != len(starts):
        raise InvalidInput(
            f"{source}.segment_names: {len(starts)} segments start in 'segments', "
            f"got {len(names)} names"
        )
    if not starts and n_segments is not None and names and len(names) != n_segments:
        raise InvalidInput(
            f"{source}.segment_names: the reference has {n_segments} segments, "
            f"got {len(names)} names"
        )
    return tuple(names), tuple(starts)


def _key_positions(doc: dict, source: str, n_segments: int | None) -> tuple[str, ...]:
    """``key_position_names``: one per segment start and one for the end, when the number of
    segments is known (0 or None: not yet)."""
    keys = doc.get("key_position_names", [])
    if not isinstance(keys, list) or not all(isinstance(n, str) and n for n in keys):
        raise InvalidInput(f"{source}.key_position_names: expected a list of non-empty strings")
    if keys and n_segments and len(keys) != n_segments + 1:
        raise InvalidInput(
            f"{source}.key_position_names: {n_segments} segments have {n_segments + 1} key "
            f"positions (each start, then the end), got {len(keys)} names"
        )
    return tuple(keys)


def _bone_numbers(doc: dict, source: str) -> tuple[np.ndarray, np.ndarray]:
    """Per-bone weights (16,) and tolerances (16,), radians."""
    weights = _per_bone(doc.get("bone_weights"), f"{source}.bone_weights", 1.0)
    if weights.sum() <= 0:
        raise InvalidInput(f"{source}.bone_weights: at least one weight must be positive")
    default_tol = _number(doc.get("default_tolerance_deg", 0.0), f"{source}.default_tolerance_deg")
    tol = _per_bone(doc.get("tolerances_deg"), f"{source}.tolerances_deg", default_tol)
    if (tol > 180).any():
        raise InvalidInput(f"{source}.tolerances_deg: tolerances must be at most 180 deg")
    return weights, np.radians(tol)


def _boundary(boundary: Any, where: str) -> tuple[tuple[str, ...], float | None]:
    """The boundary joints and direction-change threshold (thesis 5.4.2)."""
    if not isinstance(boundary, dict) or set(boundary) - {"joints", "direction_change_deg"}:
        raise InvalidInput(f"{where}: expected {{'joints': [...], 'direction_change_deg': x}}")
    joints = boundary.get("joints", [])
    if not isinstance(joints, list) or any(j not in JOINT_INDEX for j in joints):
        raise InvalidInput(f"{where}.joints: expected joint names from {list(JOINTS)}")
    change = boundary.get("direction_change_deg")
    if change is not None:
        change = _number(change, f"{where}.direction_change_deg")
        if change > 180:
            raise InvalidInput(f"{where}.direction_change_deg: expected <= 180, got {change}")
    return tuple(joints), change


def reference_segments(motion: Motion, domain: Domain | None) -> Segments:
    """The reference's segments as every analysis uses them (thesis 2.1.1 item 4, 6.8).

    The coach's ``segments`` when the domain gives them, else the boundaries detected from
    the domain's boundary joint and threshold (or the defaults); named by ``segment_names``
    when there are as many names as segments.

    Raises
    ------
    InvalidInput
        The coach's starts lie outside the reference's frames.
    """
    if domain is not None and domain.segment_starts:
        try:
            return segments_from_list(domain.segment_starts, motion, domain.segment_names or None)
        except InvalidInput as exc:
            raise InvalidInput(f"domain segments: {exc}") from None
    kw: dict[str, Any] = {}
    if domain is not None and domain.boundary_joints:
        kw["joint"] = domain.boundary_joints[0]
    if domain is not None and domain.direction_change_deg is not None:
        kw["threshold_deg"] = domain.direction_change_deg
    segs = reference_boundaries(motion, **kw)
    if domain is not None and len(domain.segment_names) == len(segs.starts):
        segs = Segments(segs.starts, segs.end, domain.segment_names)
    return segs


def domain_path(reference_path: str | os.PathLike[str]) -> Path:
    """``swing.bvh`` -> ``swing.domain.json`` in the same folder."""
    p = Path(reference_path)
    return p.with_name(p.stem + ".domain.json")


def load_domain(path: str | os.PathLike[str], *, n_segments: int | None = None) -> Domain:
    """Read and validate a domain file.

    Raises
    ------
    InvalidInput
        If the file is missing, not JSON, or invalid (see :func:`parse_domain`).
    """
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise InvalidInput(f"domain file {p} does not exist") from exc
    except json.JSONDecodeError as exc:
        raise InvalidInput(f"domain file {p}: not valid JSON ({exc})") from exc
    return parse_domain(doc, n_segments=n_segments, source=str(p))


def find_domain(
    reference_path: str | os.PathLike[str], *, n_segments: int | None = None
) -> Domain | None:
    """The domain file beside a reference, or None when there is none."""
    p = domain_path(reference_path)
    return load_domain(p, n_segments=n_segments) if p.exists() else None


__all__ = [
    "GOLF_SEGMENT_NAMES",
    "Domain",
    "check_variation",
    "domain_path",
    "find_domain",
    "load_domain",
    "reference_segments",
    "parse_domain",
]
