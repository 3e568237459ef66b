"""`coach view REF.bvh result.json [--port 8080] [--record out.viser]`.

The lead hooks :func:`register` into the CLI.

Serves the 3D view of an analysis with viser until interrupted, or, with ``--record``, writes
the scene as a ``.viser`` recording for static playback and exits.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "view",
        help="3D view of an analysis (viser): reference and performer, bones coloured by error",
        description=(
            "Serve a viser view of RESULT against REF.bvh: frame slider, play, candidates "
            "toggle, segment list (thesis 6.10). --record writes a .viser recording instead."
        ),
    )
    p.add_argument("reference", help="reference BVH file")
    p.add_argument("result", help="result JSON of `coach analyze`")
    p.add_argument("--port", type=int, default=8080, help="port to serve on (default 8080)")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--record", help="write a .viser recording here and exit")
    p.add_argument("--stride", type=int, default=1, help="record every n-th frame (default 1)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import viser

    from app.web_surface import load_reference, read_result
    from web.viewer.scene import build_scene, record_scene

    result = read_result(args.result)
    reference = load_reference(args.reference).motion.joints
    server = viser.ViserServer(host=args.host, port=args.port, verbose=False)
    scene = build_scene(server, reference, result, gui=args.record is None)
    try:
        if args.record:
            out = Path(args.record)
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_bytes(record_scene(scene, stride=args.stride))
            print(f"wrote {out}")
            return 0
        print(f"viewer at http://{args.host}:{server.get_port()} (Ctrl-C to stop)")
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        return 0
    finally:
        scene.close()
        server.stop()
