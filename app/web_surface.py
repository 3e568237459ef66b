"""What the web pages use from below the app, declared in one place (issue 24).

The web package builds on the app alone (web -> app -> worker -> engine,
``tests/test_structure.py``): the pages and the 3D viewer name bones, read result documents
and watch an analysis folder through this module, never by importing the worker or the
engine themselves. Every name is re-exported unchanged from :mod:`worker.engine_surface` or
:mod:`worker.contract`.
"""

from __future__ import annotations

from worker.contract import AnalysisFolder
from worker.engine_surface import (
    BONE_CHILD,
    BONE_LABELS,
    BONE_NAMES,
    BONE_PARENT,
    ERROR_RED_DEG,
    MISFIT_RGB,
    ONE_CAMERA_NOTE,
    Result,
    ResultFrame,
    ResultSegment,
    as_result,
    error_colors,
    load_candidate_chunk,
    load_prepared,
    load_reference,
    read_result,
)

__all__ = [
    "BONE_CHILD",
    "BONE_LABELS",
    "BONE_NAMES",
    "BONE_PARENT",
    "ERROR_RED_DEG",
    "MISFIT_RGB",
    "ONE_CAMERA_NOTE",
    "AnalysisFolder",
    "Result",
    "ResultFrame",
    "ResultSegment",
    "as_result",
    "error_colors",
    "load_candidate_chunk",
    "load_prepared",
    "load_reference",
    "read_result",
]
