"""Input checks before anything is accepted: videos are probed, BVH files imported.

The engine is imported only here and only for validation. Every refusal is an
:class:`engine.errors.InvalidInput` whose message a person can read.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from app.core.config import Settings
from worker.engine_surface import (
    SD_FLOOR_DEG,
    BvhLimits,
    InvalidInput,
    VideoLimits,
    build_action_model,
    check_variation,
    load_reference,
    load_takes,
    plot_takes,
    reference_segments,
    write_bvh,
)
from worker.engine_surface import parse_domain as engine_parse
from worker.engine_surface import probe_video as engine_probe


def probe_video(path: Path, settings: Settings) -> dict[str, Any]:
    """Open the video and decode its first frames; returns what the probe learned."""
    limits = VideoLimits(
        max_duration_s=settings.max_video_duration_s, max_bytes=settings.max_video_bytes
    )
    try:
        info = engine_probe(path, limits)
    except InvalidInput as exc:
        raise InvalidInput(_hide_paths(str(exc), path)) from None
    return {
        "frames": int(info.frames),
        "fps": float(info.fps),
        "width": int(info.width),
        "height": int(info.height),
        "duration_s": float(info.duration_s),
        "codec": str(info.codec),
    }


def _hide_paths(message: str, path: Path) -> str:
    """Server paths stay on the server: FFmpeg quotes the full path in its errors."""
    for p in (str(path.resolve()), str(path)):
        message = message.replace(p, path.name)
    return message


class InvalidDomain(InvalidInput):
    """The domain configuration does not fit the reference it comes with."""


#: Keys of the domain JSON used at import (the rest is engine.reference.domain's format,
#: segment starts included).
IMPORT_KEYS = ("mapping", "units_to_m")


def engine_domain(domain: dict[str, Any]) -> dict[str, Any]:
    """The part of the domain JSON that is the engine's domain document (each analysis
    request carries it: ``AnalysisJob.domain``); the rest says how to import the BVH."""
    return {k: v for k, v in domain.items() if k not in IMPORT_KEYS}


def parse_domain(raw: bytes) -> dict[str, Any]:
    """A domain configuration: one JSON object. Import keys ``mapping`` (our joint -> BVH
    joint) and ``units_to_m``, plus the engine's domain format (segment starts and names,
    bone weights, tolerances, boundary joints: engine.reference.domain)."""
    try:
        data = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise InvalidInput(f"the domain configuration is not valid JSON ({exc})") from exc
    if not isinstance(data, dict):
        raise InvalidInput("the domain configuration must be a JSON object")
    mapping = data.get("mapping")
    if mapping is not None and not (
        isinstance(mapping, dict)
        and all(isinstance(k, str) and isinstance(v, str) for k, v in mapping.items())
    ):
        raise InvalidInput("domain 'mapping' must be an object of joint name -> BVH joint name")
    units = data.get("units_to_m")
    if units is not None and not (
        isinstance(units, int | float) and math.isfinite(units) and units > 0
    ):
        raise InvalidInput("domain 'units_to_m' must be a positive number")
    engine_parse(engine_domain(data), source="domain configuration")
    return data


def reference_limits(settings: Settings) -> BvhLimits:
    """The engine's BVH limits from the service settings (6 channels per joint at most)."""
    return BvhLimits(
        max_frames=settings.max_reference_frames,
        max_duration_s=settings.max_reference_duration_s,
        max_joints=settings.max_reference_joints,
        max_channels=6 * settings.max_reference_joints,
    )


def inspect_reference(
    path: Path, domain: dict[str, Any] | None, settings: Settings | None = None
) -> dict[str, Any]:
    """Import the BVH onto the 17-joint body (refusing unmappable files, naming the missing
    joints) and return the derived description stored with the reference.

    With ``settings``, files over its reference limits are refused as they are read (an
    upload); without, any file is read (one already on the server: the demo, migrations).

    ``segments`` holds the segment boundaries every analysis of this reference uses (the
    domain's starts, or those detected from the motion), then the last frame: n + 1 frame
    numbers for n segments. Segment names that do not match their number are refused here,
    where the coach can fix them, rather than dropped at analysis time.
    """
    domain = domain or {}
    ref = load_reference(
        path, mapping=domain.get("mapping"), units_to_m=domain.get("units_to_m"),
        limits=reference_limits(settings) if settings is not None else None,
    )  # fmt: skip
    motion = ref.motion
    knowledge = engine_parse(engine_domain(domain), source="domain configuration")
    try:
        segs = reference_segments(motion, knowledge)
    except InvalidInput as exc:  # the coach's starts lie outside the motion
        raise InvalidDomain(str(exc)) from None
    try:
        check_variation(motion, knowledge)
    except InvalidInput as exc:
        raise InvalidDomain(str(exc)) from None
    names = knowledge.segment_names
    if names and len(names) != len(segs.starts):
        found = ", ".join(str(s) for s in segs.starts)
        raise InvalidDomain(
            f"domain segment_names: the motion has {len(segs.starts)} segments (detected, "
            f"starting at frames {found}), got {len(names)} names; give their starts in "
            "'segments' to set them yourself"
        )
    return {
        "frames": int(motion.frames),
        "fps": float(motion.fps),
        "duration_s": float(motion.duration_s),
        "first_motion_frame": int(motion.first_motion_frame),
        "profile": str(ref.profile),
        "source_joints": list(ref.source_joint_names),
        "segments": [*segs.starts, segs.end],
    }


def build_from_takes(
    paths: list[Path], names: list[str], out_dir: Path, settings: Settings, sport: str = ""
) -> tuple[dict[str, Any], dict[str, Any]]:
    """A reference from several takes of one action (seed 002): the mean performance is
    written to ``out_dir/reference.bvh`` and the synchronisation plot to ``takes.png``.

    Returns the domain configuration (with the expert's spread per frame) and the derived
    description, whose ``takes`` says which takes were kept, the median and what was left
    out and why.

    Raises
    ------
    InvalidInput
        A take that is not BVH, cannot be mapped, is over the limits, or fewer than two
        takes of one action (the message names the take).
    """
    takes = load_takes(paths, reference_limits(settings), names)
    model = build_action_model(takes)
    bvh = write_bvh(out_dir / "reference.bvh", model.file_joints, model.fps, model.shape)
    plot_takes(model, out_dir / "takes.png")
    domain = model.domain_doc(sport=sport, sd_floor_deg=SD_FLOOR_DEG)
    derived = inspect_reference(bvh, domain)
    derived["takes"] = model.summary()
    return domain, derived
