"""The engine as the service sees it: every engine name that the app uses (and, through
:mod:`app.web_surface`, the web pages), declared in one place (issue 24).

The layers import strictly downwards, app -> worker -> engine and web -> app
(``tests/test_structure.py``). The worker runs the engine (:mod:`worker.jobs`); the app needs
a few of its pieces in-process as well: checking an upload before it is queued, reading a
result document, drawing a skeleton on a frame, naming bones. They come from here, so a
reader sees the whole seam in one file, and a change to what the service relies on shows up
in this file's diff.

Every name is the engine's own object, re-exported unchanged, except the two stage-output
loaders at the end: only the live 3D view reads stage outputs, and their modules cost about
a second and 40 MB to import, so they load on first use.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

# Bones, joints and their names for people (DESIGN.md "Skeleton").
from engine.body.limits import JOINT_ANGLES, joint_angles_deg
from engine.body.posture_angles import POSTURE_ANGLES, posture_angles_deg
from engine.body.skeleton import (
    BEND_LABELS,
    BONE_CHILD,
    BONE_LABELS,
    BONE_NAMES,
    BONE_PARENT,
    JOINTS,
    bone_label,
    column_name,
)

# The command line: the engine's own `coach` subcommands.
from engine.cli import add_engine_commands, run_parsed

# Errors a user can correct (a message for them, never a traceback).
from engine.errors import InvalidInput

# Inputs: what an upload is checked with before anything is queued.
from engine.io.bvh import BvhLimits, load_reference, write_bvh
from engine.io.encode import write_video

# The result document (DESIGN.md "Result of an analysis"), read typed.
from engine.io.result_reader import Result, ResultFrame, ResultSegment, as_result, read_result
from engine.io.video import VideoLimits, probe_video
from engine.reference.action_model import SD_FLOOR_DEG, build_action_model, load_takes
from engine.reference.domain import check_variation, parse_domain, reference_segments
from engine.reference.takes_plot import plot_takes

# How results are drawn and worded for a coach.
from engine.report import (
    ERROR_RED_DEG,
    MISFIT_RGB,
    ONE_CAMERA_NOTE,
    draw_skeleton,
    error_colors,
    tempo_words,
)
from engine.stages.framing import check_framing

# The embedded demo: a performer rendered from a reference.
from engine.synth import SynthSettings, synthesize

if TYPE_CHECKING:
    from engine.stage_outputs import CandidateChunk, Prepared

__all__ = [
    "BEND_LABELS",
    "BONE_CHILD",
    "BONE_LABELS",
    "BONE_NAMES",
    "BONE_PARENT",
    "ERROR_RED_DEG",
    "JOINTS",
    "JOINT_ANGLES",
    "POSTURE_ANGLES",
    "MISFIT_RGB",
    "ONE_CAMERA_NOTE",
    "SD_FLOOR_DEG",
    "BvhLimits",
    "InvalidInput",
    "Result",
    "ResultFrame",
    "ResultSegment",
    "SynthSettings",
    "VideoLimits",
    "add_engine_commands",
    "as_result",
    "bone_label",
    "build_action_model",
    "check_framing",
    "check_variation",
    "column_name",
    "draw_skeleton",
    "error_colors",
    "joint_angles_deg",
    "posture_angles_deg",
    "load_candidate_chunk",
    "load_prepared",
    "load_reference",
    "load_takes",
    "parse_domain",
    "plot_takes",
    "probe_video",
    "read_result",
    "reference_segments",
    "run_parsed",
    "synthesize",
    "tempo_words",
    "write_bvh",
    "write_video",
]


def load_prepared(path: Path) -> Prepared:
    """Stage 2's output (``AnalysisFolder.prepared``), for the live 3D view."""
    from engine.stage_outputs import Prepared

    return Prepared.load(path)


def load_candidate_chunk(path: Path) -> CandidateChunk:
    """One finished stage-3 chunk (``AnalysisFolder.finished_chunks()``), for the live view."""
    from engine.stage_outputs import CandidateChunk

    return CandidateChunk.load(path)
