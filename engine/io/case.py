"""Writing a synthetic case folder: ``reference.bvh``, ``video.mp4``, ``truth.json`` (DESIGN.md).

Files are written under temporary names and renamed when complete, so a folder never holds a
half-written video or truth next to complete ones.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from engine.errors import InvalidInput
from engine.io.encode import write_video


class CaseLike(Protocol):
    """What :func:`write_case` reads of a case (e.g. :class:`engine.synth.SynthCase`).

    A protocol rather than an import, so that ``io`` (the edge) does not depend on
    :mod:`engine.synth`, which sits above it.
    """

    # read-only: a frozen dataclass (engine.synth.SynthCase) must satisfy the protocol
    @property
    def frames(self) -> np.ndarray:
        """RGB video frames, uint8, shape (T', H, W, 3)."""
        ...

    @property
    def fps(self) -> float: ...

    @property
    def truth(self) -> dict[str, Any]:
        """``truth.json`` content (DESIGN.md "Synthetic cases")."""
        ...


def write_case(case: CaseLike, out_dir: str | Path, reference_path: str | Path) -> dict:
    """Write a synthetic case folder.

    Parameters
    ----------
    case : CaseLike
        From :func:`engine.synth.synthesize`.
    out_dir : str or Path
        Folder to create (or fill; existing case files are replaced).
    reference_path : str or Path
        The reference BVH the case was made from; copied as ``reference.bvh``.

    Returns
    -------
    written : dict
        ``{"dir", "reference", "video", "truth"}`` paths as str and ``"codec"`` (``"h264"``
        or ``"mp4v"``).

    Raises
    ------
    InvalidInput
        When ``reference_path`` is not a file.
    """
    ref = Path(reference_path)
    if not ref.is_file():
        raise InvalidInput(f"reference_path {str(ref)!r} is not a file")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)

    ref_out = out / "reference.bvh"
    if ref.resolve() != ref_out.resolve():
        shutil.copyfile(ref, _tmp(ref_out))
        os.replace(_tmp(ref_out), ref_out)

    video = out / "video.mp4"
    tmp_video = out / "video.part.mp4"  # keeps the .mp4 suffix: the muxer is chosen by it
    codec = write_video(tmp_video, case.frames, case.fps)
    os.replace(tmp_video, video)

    truth = dict(case.truth)
    truth["video"] = {**truth.get("video", {}), "codec": codec, "file": video.name}
    truth_path = out / "truth.json"
    with open(_tmp(truth_path), "w", encoding="utf-8") as fh:
        json.dump(truth, fh, separators=(",", ":"))
    os.replace(_tmp(truth_path), truth_path)
    return {
        "dir": str(out),
        "reference": str(ref_out),
        "video": str(video),
        "truth": str(truth_path),
        "codec": codec,
    }


def _tmp(path: Path) -> Path:
    return path.with_name(path.name + ".part")
