"""`coach reference build TAKE.bvh TAKE.bvh ... --out REF`: a reference from several takes.

Seed 002: the takes are synchronised to their median take, and the mean performance with the
expert's spread of every bone at every frame is learnt from them. Writes

    REF.bvh          the mean performance, on the median take's frames and body
    REF.domain.json  its domain, with the spread (``variation``): ``coach analyze REF.bvh``
                     then reports errors against the expert's own variation as well
    REF.model.npz    the whole action model (aSpace, warps, mean, spread, motion direction)

``--plot`` draws seed 002 fig. 5: the first aSpace dimensions before and after the
synchronisation, and the mean +- 3 sd.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from engine.errors import InvalidInput
from engine.reference.action_model import SD_FLOOR_DEG


def register(sub: argparse._SubParsersAction) -> None:
    q = sub.add_parser(
        "build",
        help="learn a reference from several takes of one action (seed 002)",
        description=__doc__.splitlines()[0],
    )
    q.add_argument("takes", nargs="+", type=Path, help="two or more BVH takes of one action")
    q.add_argument("--out", type=Path, required=True, help="output stem: writes OUT.bvh, ...")
    q.add_argument("--plot", type=Path, default=None, help="write a PNG as seed 002 fig. 5")
    q.add_argument("--mu", type=float, default=None, help="smoothness (default: eq. 20)")
    q.add_argument("--sport", default="", help="sport named in the domain file")
    q.add_argument(
        "--sd-floor-deg", type=float, default=SD_FLOOR_DEG,
        help=f"smallest spread a z-score divides by (default {SD_FLOOR_DEG:g})",
    )  # fmt: skip
    q.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from engine.reference.action_model import TakesSettings, build_action_model, load_takes
    from engine.reference.takes_plot import plot_takes

    if len(args.takes) < 2:
        raise InvalidInput("give at least two takes")
    takes = load_takes(args.takes)
    model = build_action_model(takes, TakesSettings(mu=args.mu))
    paths = write_model(model, args.out, sport=args.sport, sd_floor_deg=args.sd_floor_deg)
    for line in describe(model):
        print(line)
    for p in paths:
        print(f"written {p}")
    if args.plot is not None:
        plot_takes(model, args.plot)
        print(f"plot written to {args.plot}")
    return 0


def write_model(model, out: Path, *, sport: str = "", sd_floor_deg: float = SD_FLOOR_DEG):
    """The mean performance as BVH, its domain with the spread, the model as npz."""
    from engine.io.bvh import write_bvh

    out = out.with_suffix("") if out.suffix == ".bvh" else out
    out.parent.mkdir(parents=True, exist_ok=True)
    bvh = write_bvh(out.with_suffix(".bvh"), model.file_joints, model.fps, model.shape)
    dom = out.with_name(out.name + ".domain.json")
    dom.write_text(json.dumps(model.domain_doc(sport=sport, sd_floor_deg=sd_floor_deg)),
                   encoding="utf-8")  # fmt: skip
    npz = out.with_name(out.name + ".model.npz")
    np.savez_compressed(npz, summary=json.dumps(model.summary()), **model.arrays())
    return [bvh, dom, npz]


def describe(model) -> list[str]:
    """Lines of the build report."""
    from engine.body.skeleton import BONE_LABELS

    s = model.summary()
    out = [
        f"takes       {len(s['takes'])}: {', '.join(s['takes'])}",
        f"kept        {len(s['kept'])}: {', '.join(s['kept'])}",
        f"median take {s['median_take']} ({s['frames']} frames at {s['fps']:.3f} fps)",
        f"aSpace      {s['aspace_dims']} dimensions, {s['aspace_explained']:.1%} of the variance",
    ]
    for w in s["warnings"]:
        out.append(f"warning     {w}")
    for i in np.flatnonzero(model.kept):
        sy = model.syncs[i]
        out.append(
            f"  {model.names[i]:>12}: to the median {sy.distance:7.3f} (eq. 12 per frame), "
            f"warp roughness {sy.roughness:6.1f} frames, mu {sy.mu:.3f}"
        )
    sd = np.degrees(model.bone_sd)
    out.append("spread of the expert's bones (deg, mean and max over frames):")
    for b in np.argsort(-sd.mean(0)):
        out.append(f"  {BONE_LABELS[b]:>22} {sd[:, b].mean():5.1f} {sd[:, b].max():6.1f}")
    return out
