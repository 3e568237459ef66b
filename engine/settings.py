"""One typed settings object for the whole engine, gathering each stage's own.

Every stage module defines a frozen dataclass of its tuning with documented thesis defaults;
:class:`Settings` holds one of each. Services pass settings as a small JSON dict (nested by
stage), turned into a :class:`Settings` by :meth:`Settings.from_dict`, which refuses unknown
keys so a typo never silently falls back to a default.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from engine.errors import InvalidInput
from engine.io.video import VideoLimits
from engine.stages.alignment import AlignmentSettings
from engine.stages.calibration import CalibrationSettings
from engine.stages.candidates import CandidateSettings
from engine.stages.foreground import ForegroundSettings
from engine.stages.perception import PerceptionSettings
from engine.stages.selection import SelectionSettings


@dataclass(frozen=True)
class Settings:
    """Settings of one analysis.

    Attributes
    ----------
    working_height : int
        Height in pixels the video is scaled to before any stage (aspect kept); thesis
        experiments use 320 x 240.
    seed : int
        Seed of every random choice (stage 3 sampling), so an analysis can be repeated.
    chunk_frames : int
        Video frames per stage-3 chunk (the unit fanned out across workers).
    video, perception, foreground, calibration, alignment, candidates, selection
        Each stage's own settings.
    """

    working_height: int = 240
    seed: int = 0
    chunk_frames: int = 16
    video: VideoLimits = field(default_factory=VideoLimits)
    perception: PerceptionSettings = field(default_factory=PerceptionSettings)
    foreground: ForegroundSettings = field(default_factory=ForegroundSettings)
    calibration: CalibrationSettings = field(default_factory=CalibrationSettings)
    alignment: AlignmentSettings = field(default_factory=AlignmentSettings)
    candidates: CandidateSettings = field(default_factory=CandidateSettings)
    selection: SelectionSettings = field(default_factory=SelectionSettings)

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> Settings:
        """Settings from a nested dict, e.g. ``{"candidates": {"n_samples": 20}}``.

        A ``"preset"`` key (``"default"``, ``"fast"`` or ``"thesis"``) picks the starting point.

        Raises
        ------
        InvalidInput
            Unknown preset, section or key, or a value of the wrong kind.
        """
        d = dict(d or {})
        preset = d.pop("preset", "default")
        if preset not in PRESETS:
            raise InvalidInput(f"settings preset must be one of {sorted(PRESETS)}, got {preset!r}")
        return _merge(PRESETS[preset], d, "settings")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready nested dict (tuples become lists)."""
        return dataclasses.asdict(self)


def _merge(obj: Any, changes: dict[str, Any], where: str) -> Any:
    names = {f.name: f for f in dataclasses.fields(obj)}
    updates: dict[str, Any] = {}
    for key, value in changes.items():
        if key not in names:
            raise InvalidInput(f"unknown setting {where}.{key}; known: {sorted(names)}")
        current = getattr(obj, key)
        if dataclasses.is_dataclass(current):
            if not isinstance(value, dict):
                raise InvalidInput(f"{where}.{key} must be an object of settings")
            updates[key] = _merge(current, value, f"{where}.{key}")
        elif isinstance(current, tuple):
            updates[key] = tuple(value) if isinstance(value, list | tuple) else value
        elif isinstance(current, bool) and not isinstance(value, bool):
            raise InvalidInput(f"{where}.{key} must be true or false, got {value!r}")
        elif isinstance(current, int | float) and not isinstance(value, int | float):
            raise InvalidInput(f"{where}.{key} must be a number, got {value!r}")
        else:
            updates[key] = value
    return dataclasses.replace(obj, **updates)


#: Named starting points. "fast" trades stage-3 accuracy for speed (previews, tests, demos).
#: It keeps stage 0's GrabCut: without it a performer who hardly moves leaves the background
#: between the legs unseen and the legs merge into one block; on the 160x120 test case
#: (tests/engine/test_pipeline.py) stage 2's C was then 16 reference frames off instead of
#: 1.2, for 0.2 s saved.
#: "thesis" is the thesis' own evidence only: no learned mask or keypoints in any stage.
PRESETS: dict[str, Settings] = {
    "default": Settings(),
    "thesis": Settings(
        perception=PerceptionSettings(enabled=False),
        foreground=ForegroundSettings(fuse_learned=False),
        calibration=CalibrationSettings(keypoint_weight=0.0, perspective=False),
        alignment=AlignmentSettings(keypoint_weight=0.0),
        candidates=CandidateSettings(keypoint_weight=0.0),
    ),
    "fast": Settings(
        candidates=CandidateSettings(n_samples=16, n_iterations=5, refine_sweeps=2,
                                     refine_step0_deg=2.0,
                                     n_candidates=8),  # fmt: skip
    ),
}
