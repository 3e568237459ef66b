"""`coach reference inspect REF.bvh`: what the engine reads from a reference motion.

Prints frames, frame rate, duration, the joint mapping (source name -> our name), whether a
conversion T-pose was detected, and the segment boundaries (thesis 5.4.2) with frame numbers
and times; ``--plot`` draws the chosen joint's speed and velocity-direction change with the
threshold and the boundaries marked.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from engine.body.skeleton import JOINTS
from engine.commands import reference_build


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "reference",
        help="inspect a reference motion (BVH), or build one from several takes",
        description="Tools for reference motions (BVH).",
    )
    sub = p.add_subparsers(dest="reference_command", required=True)
    q = sub.add_parser(
        "inspect",
        help="print frames, joint mapping, T-pose and segment boundaries",
        description=__doc__.splitlines()[0],
    )
    q.add_argument("bvh", type=Path, help="reference BVH file")
    q.add_argument(
        "--plot", type=Path, default=None, help="write a PNG of speed and direction change"
    )
    q.add_argument(
        "--joint",
        default="r_wrist",
        choices=JOINTS,
        help="joint whose direction changes mark boundaries (default r_wrist)",
    )
    q.add_argument(
        "--threshold-deg",
        type=float,
        default=60.0,
        help="smallest direction change at a boundary, degrees (default 60)",
    )
    q.add_argument(
        "--min-segment-s", type=float, default=0.4, help="shortest segment, seconds (default 0.4)"
    )
    q.add_argument(
        "--units-to-m", type=float, default=None, help="metres per file unit (default: guessed)"
    )
    q.set_defaults(func=run)
    reference_build.register(sub)


def run(args: argparse.Namespace) -> int:
    from engine.io.bvh import load_reference
    from engine.reference.boundaries import reference_boundaries
    from engine.reference.domain import domain_path, find_domain, reference_segments

    ref = load_reference(args.bvh, units_to_m=args.units_to_m)
    m = ref.motion
    domain = find_domain(args.bvh)
    if domain is not None and domain.segment_starts:  # what every analysis of it will use
        seg = reference_segments(m, domain)
        source = f"set by {domain_path(args.bvh).name}"
    else:
        seg = reference_boundaries(
            m, joint=args.joint, threshold_deg=args.threshold_deg, min_segment_s=args.min_segment_s
        )
        source = f"{args.joint} velocity direction change > {args.threshold_deg:g} deg"
    for line in describe(ref, seg, source):
        print(line)
    if args.plot is not None:
        plot(ref, seg, args.joint, args.threshold_deg, args.plot)
        print(f"plot written to {args.plot}")
    return 0


def describe(ref, seg, source: str) -> list[str]:
    """Lines of the inspection report; ``source`` says where the segments come from."""
    m = ref.motion
    h = float(ref.shape.height * 1.04)
    out = [
        f"reference   {m.name}",
        f"frames      {m.frames} at {m.fps:.3f} fps, {m.duration_s:.3f} s",
        f"units       {ref.units_to_m:g} m per file unit; body height ~{h:.2f} m",
        f"heading     rotated {np.degrees(ref.heading_rad):+.2f} deg about y (faces +z at frame 0)",
        "T-pose      "
        + (
            "frame 0 is a conversion T-pose; the motion starts at frame 1"
            if ref.has_tpose
            else "none detected; the motion starts at frame 0"
        ),
        f"mapping     name table '{ref.profile}' ({len(ref.bvh.names)} source nodes)",
    ]
    for src, ours in zip(ref.source_joint_names, JOINTS, strict=True):
        out.append(f"  {src:>24} -> {ours}")
    out.append(f"segments    {len(seg.starts)} ({source})")
    for k, (a, b) in enumerate(seg.bounds()):
        out.append(f"  {k:2d}: frames {a:5d} - {b:5d}   {a / m.fps:7.3f} s - {b / m.fps:7.3f} s")
    return out


def plot(ref, seg, joint: str, threshold_deg: float, path: Path) -> None:
    """PNG of the joint's speed and direction change, threshold and boundaries marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from engine.io.figures import save_figure
    from engine.reference.boundaries import direction_change

    m = ref.motion
    speed, change = direction_change(m, joint=joint, min_speed=0.1)
    t = np.arange(m.frames)
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(10, 5.5), constrained_layout=True)
    ax1.plot(t, speed, color="tab:blue")
    ax1.axhline(0.1, color="0.5", ls=":", label="min speed (direction ignored below)")
    ax1.legend(loc="upper left", fontsize=8)
    ax1.set_ylabel(f"{joint} speed (m/s)")
    ax1.set_title(f"{m.name}: segment boundaries from {joint} direction change")
    ax2.plot(t, np.degrees(change), color="tab:orange", label="direction change")
    ax2.axhline(threshold_deg, color="tab:red", ls="--", label=f"threshold {threshold_deg:g} deg")
    ax2.set_ylabel("direction change (deg)")
    ax2.set_xlabel(f"reference frame ({m.fps:.0f} fps)")
    ax2.set_ylim(0, 180)
    for ax in (ax1, ax2):
        for s in seg.starts[1:]:
            ax.axvline(s, color="k", lw=1)
        if m.first_motion_frame:
            ax.axvspan(0, m.first_motion_frame, color="0.85")
    for s in seg.starts[1:]:
        ax2.annotate(f"{s}", (s, 170), ha="left", va="top", fontsize=8)
    ax2.legend(loc="upper left", fontsize=8)
    save_figure(fig, path, dpi=100)
