"""`coach analyze REF.bvh VIDEO --out result.json [--report report.html]`: the whole registration.

Uses :func:`engine.pipeline.analyze` when the pipeline module provides it; until then it runs
the stages here in order (thesis 4.1-4.7). A stage that is not available yet is replaced by a
documented stand-in and recorded in the result's ``notes`` (stage 2: a uniform C).
"""

from __future__ import annotations

import argparse
import importlib
import time
from pathlib import Path
from typing import Any

import numpy as np

from engine.errors import InvalidInput


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "analyze",
        help="register a performer video against a reference BVH and report posture errors",
        description=(
            "Register VIDEO against REF.bvh (thesis chapter 4): temporal correspondence, "
            "posture candidates, selection, per-frame/bone/segment errors. A domain file "
            "REF.domain.json beside the BVH (thesis 6.8) names segments and weights bones."
        ),
    )
    p.add_argument("reference", help="reference BVH file")
    p.add_argument("video", help="performer video file")
    p.add_argument("--out", required=True, help="result JSON to write")
    p.add_argument("--report", help="also write a self-contained HTML report here")
    p.add_argument("--frames", help="analyse only video frames A:B (Python slice, B exclusive)")
    p.add_argument("--fast", action="store_true", help="fewer samples and candidates (previews)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=run)


def parse_frames(spec: str | None, n: int) -> tuple[int, int]:
    """``"A:B"`` -> (A, B) clipped to [0, n]; None -> (0, n).

    Raises
    ------
    InvalidInput
        Malformed or empty range (names ``--frames``).
    """
    if not spec:
        return 0, n
    parts = spec.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        a = int(parts[0]) if parts[0] else 0
        b = int(parts[1]) if parts[1] else n
    except ValueError as exc:
        raise InvalidInput(f"--frames: expected A:B (e.g. 10:200), got {spec!r}") from exc
    a, b = max(0, a if a >= 0 else n + a), min(n, b if b >= 0 else n + b)
    if b - a < 2:
        raise InvalidInput(
            f"--frames: {spec!r} leaves {max(b - a, 0)} frames of {n}; need at least 2"
        )
    return a, b


def _progress(quiet: bool):
    def report(stage: str, fraction: float) -> None:
        if not quiet:
            print(f"\r{stage:>12s} {100 * fraction:5.1f} %", end="", flush=True)

    return report


def _module(name: str) -> Any | None:
    try:
        return importlib.import_module(name)
    except ImportError:
        return None


def _run_stages(args: argparse.Namespace) -> tuple[dict[str, Any], np.ndarray]:
    """Stages 0-4 run here directly; returns (result document, analysed RGB frames)."""
    from engine.io.bvh import load_reference
    from engine.io.result import build_result
    from engine.io.video import read_video
    from engine.reference.boundaries import reference_boundaries
    from engine.reference.domain import find_domain
    from engine.stages.calibration import calibrate
    from engine.stages.candidates import CandidateSettings, estimate_candidates
    from engine.stages.foreground import extract_foreground
    from engine.stages.selection import SelectionSettings, select_and_refine
    from engine.types import Segments

    on_progress = _progress(args.quiet)
    timing: dict[str, float] = {}
    notes: list[str] = []
    t0 = time.perf_counter()
    ref = load_reference(args.reference)
    motion = ref.motion
    first = motion.first_motion_frame
    ref_joints = motion.joints[first:]
    video = read_video(args.video)
    a, b = parse_frames(args.frames, video.frames.shape[0])
    frames = video.frames[a:b]
    timing["load"] = time.perf_counter() - t0

    # reference boundaries, relative to the trimmed reference (T-pose skipped)
    domain = find_domain(args.reference)
    kw = {}
    if domain is not None and domain.boundary_joints:
        kw["joint"] = domain.boundary_joints[0]
    if domain is not None and domain.direction_change_deg is not None:
        kw["threshold_deg"] = domain.direction_change_deg
    segs = reference_boundaries(motion, **kw)
    rel = Segments(tuple(s - first for s in segs.starts), segs.end - first, segs.names)
    if domain is not None and domain.segment_names and len(domain.segment_names) == len(rel.starts):
        rel = Segments(rel.starts, rel.end, domain.segment_names)

    t = time.perf_counter()
    fg = extract_foreground(frames, on_progress=on_progress)
    timing["foreground"] = time.perf_counter() - t
    t = time.perf_counter()
    camera, _ = calibrate(
        ref_joints[0], ref.shape, fg.silhouettes[0], fg.edges[0], on_progress=on_progress
    )
    timing["calibration"] = time.perf_counter() - t

    t = time.perf_counter()
    n = frames.shape[0]
    alignment = _module("engine.stages.alignment")
    C0 = np.linspace(0, ref_joints.shape[0] - 1, n)
    R = np.repeat(np.eye(3)[None], n, 0)
    if alignment is not None and hasattr(alignment, "align"):
        out = alignment.align(
            ref_joints, ref.shape, camera, fg.silhouettes, fg.skin, on_progress=on_progress
        )
        C0 = np.asarray(out.C, float)
        R = np.asarray(out.rotations, float)
    else:
        notes.append("stage 2 unavailable: uniform temporal correspondence used as C")
    timing["alignment"] = time.perf_counter() - t

    t = time.perf_counter()
    cs = CandidateSettings()
    if args.fast:
        cs = CandidateSettings(n_samples=15, n_iterations=5, n_candidates=8, refine_sweeps=2)
    rng = np.random.default_rng(args.seed)
    cands, cflags, prev = [], [], None
    for i in range(n):
        ref_t = ref_joints[int(round(C0[i]))]
        hip = ref_t[0]
        init = (ref_t - hip) @ R[i].T + hip
        fc = estimate_candidates(
            fg.silhouettes[i], fg.edges[i], camera, ref.shape, init, settings=cs, rng=rng, prev=prev
        )
        cands.append(fc.candidates)
        cflags.append(tuple(fg.flags[i]) + tuple(fc.flags))
        prev = fc
        on_progress("candidates", (i + 1) / n)
    timing["candidates"] = time.perf_counter() - t

    t = time.perf_counter()
    ss = SelectionSettings()
    if domain is not None and domain.boundary_joints:
        ss = SelectionSettings(boundary_joints=domain.boundary_joints)
    if domain is not None and domain.direction_change_deg is not None:
        ss = SelectionSettings(
            boundary_joints=ss.boundary_joints, direction_change_deg=domain.direction_change_deg
        )
    sel = select_and_refine(
        cands, ref_joints, rel, C0, settings=ss, fps_ratio=motion.fps / video.fps,
        candidate_flags=cflags, on_progress=on_progress,
    )  # fmt: skip
    timing["selection"] = time.perf_counter() - t
    timing["total"] = time.perf_counter() - t0
    doc = build_result(
        reference_name=motion.name, reference_frames=motion.frames, reference_fps=motion.fps,
        video={"frames": video.frames.shape[0], "fps": video.fps,
               "width": frames.shape[2], "height": frames.shape[1]},
        camera=camera, selection=sel, candidates=cands, timing_s=timing, domain=domain,
        reference_frame_offset=first, video_frame_offset=a,
    )  # fmt: skip
    doc["notes"] = notes
    return doc, frames


def run(args: argparse.Namespace) -> int:
    from engine.io.result import write_result, write_text
    from engine.report import build_report_html

    for name in ("reference", "video"):
        if not Path(getattr(args, name)).exists():
            raise InvalidInput(f"{name}: {getattr(args, name)} does not exist")
    doc, frames = _run_stages(args)
    write_result(doc, args.out)
    if not args.quiet:
        print(f"\nwrote {args.out}: mean posture error {doc['summary']['mean_error_deg']:.1f} deg")
        for m in doc["summary"]["messages"]:
            print(f"  {m}")
    if args.report:
        write_text(build_report_html(doc, frames), args.report)
        if not args.quiet:
            print(f"wrote {args.report}")
    return 0
