"""Video writing: H.264 MP4 that OpenCV and browsers play (synthetic cases, overlays).

PyAV encodes with libx264 into yuv420p with the ``moov`` atom at the front (faststart), so a
browser can start playing before the whole file has arrived. Only when this PyAV build has no
H.264 encoder does it fall back to OpenCV's MPEG-4 Part 2 (``mp4v``), which OpenCV reads but
most browsers do not; the codec actually used is returned so callers can say so.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np

from engine.errors import InvalidInput


def write_video(path: str | Path, frames: np.ndarray, fps: float, *, crf: int = 18) -> str:
    """Write RGB frames to an MP4 file.

    Parameters
    ----------
    path : str or Path
        Output file (parent directories must exist); overwritten.
    frames : ndarray of uint8, shape (T', H, W, 3)
        RGB images; H and W must be even (yuv420p halves the chroma resolution).
    fps : float
        Frame rate (fractional rates such as 12.5 are kept exactly as a rational time base).
    crf : int
        x264 constant rate factor (0 lossless .. 51 worst); 18 is visually lossless.

    Returns
    -------
    codec : str
        ``"h264"`` or, when this PyAV has no libx264, ``"mp4v"``.

    Raises
    ------
    InvalidInput
        Empty or wrongly shaped frames, odd image size, fps <= 0.
    """
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.shape[0] < 1:
        raise InvalidInput(f"frames must have shape (T, H, W, 3) with T >= 1, got {frames.shape}")
    if frames.dtype != np.uint8:
        raise InvalidInput(f"frames must be uint8, got {frames.dtype}")
    _, H, W, _ = frames.shape
    if H % 2 or W % 2:
        raise InvalidInput(f"frame width and height must be even for yuv420p, got {W}x{H}")
    if not np.isfinite(fps) or fps <= 0:
        raise InvalidInput(f"fps must be positive, got {fps!r}")
    import av

    if "libx264" in av.codecs_available:
        _write_pyav(Path(path), frames, fps, crf)
        return "h264"
    _write_opencv(Path(path), frames, fps)
    return "mp4v"


def _write_pyav(path: Path, frames: np.ndarray, fps: float, crf: int) -> None:
    import av

    rate = Fraction(fps).limit_denominator(1001)
    with av.open(str(path), mode="w", options={"movflags": "+faststart"}) as container:
        stream = container.add_stream("libx264", rate=rate)
        stream.width, stream.height = frames.shape[2], frames.shape[1]
        stream.pix_fmt = "yuv420p"
        # main profile and no B-frame pyramids: plays in every browser and in OpenCV
        stream.options = {"crf": str(int(crf)), "preset": "medium", "profile": "main"}
        for img in frames:
            frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(img), format="rgb24")
            for packet in stream.encode(frame):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def _write_opencv(path: Path, frames: np.ndarray, fps: float) -> None:
    import cv2

    H, W = frames.shape[1:3]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"mp4v"), float(fps), (W, H))
    if not writer.isOpened():
        raise InvalidInput(f"cannot open {path} for writing")
    try:
        for img in frames:
            writer.write(np.ascontiguousarray(img[..., ::-1]))  # OpenCV wants BGR
    finally:
        writer.release()
