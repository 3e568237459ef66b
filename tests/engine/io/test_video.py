"""Video input: decoding, working resolution, and refusal of bad files."""

from __future__ import annotations

from pathlib import Path

import av
import numpy as np
import pytest

from engine.errors import InvalidInput
from engine.io.video import VideoLimits, probe_video, read_video


def write_video(path: Path, n: int, w: int = 64, h: int = 48, fps: int = 10) -> Path:
    with av.open(str(path), "w") as c:
        s = c.add_stream("mpeg4", rate=fps)
        s.width, s.height, s.pix_fmt = w, h, "yuv420p"
        for i in range(n):
            img = np.full((h, w, 3), 20 * i % 255, np.uint8)
            for p in s.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                c.mux(p)
        for p in s.encode():
            c.mux(p)
    return path


def test_read_scales_and_keeps_timestamps(tmp_path):
    p = write_video(tmp_path / "a.mp4", 6)
    v = read_video(p, height=96)
    assert v.frames.shape == (6, 96, 128, 3) and v.frames.dtype == np.uint8
    assert v.scale == pytest.approx(2.0)
    assert v.fps == pytest.approx(10.0)
    np.testing.assert_allclose(v.timestamps_s, np.arange(6) / 10.0, atol=1e-6)


def test_probe_is_cheap_and_reports(tmp_path):
    info = probe_video(write_video(tmp_path / "a.mp4", 5))
    assert (info.width, info.height, info.frames) == (64, 48, 5)


def test_not_a_video(tmp_path):
    p = tmp_path / "x.mp4"
    p.write_text("hello, not a video")
    with pytest.raises(InvalidInput, match="not a readable video"):
        probe_video(p)


def test_missing_and_empty(tmp_path):
    with pytest.raises(InvalidInput, match="does not exist"):
        probe_video(tmp_path / "nope.mp4")
    (tmp_path / "e.mp4").write_bytes(b"")
    with pytest.raises(InvalidInput, match="empty"):
        probe_video(tmp_path / "e.mp4")


def test_truncated(tmp_path):
    p = write_video(tmp_path / "a.mp4", 10)
    data = p.read_bytes()
    t = tmp_path / "t.mp4"
    t.write_bytes(data[: len(data) // 3])
    with pytest.raises(InvalidInput, match="not a readable video|frame|decod"):
        read_video(t)


def test_single_frame(tmp_path):
    with pytest.raises(InvalidInput, match="at least 2"):
        probe_video(write_video(tmp_path / "one.mp4", 1))


def test_over_limits(tmp_path):
    p = write_video(tmp_path / "a.mp4", 20)
    with pytest.raises(InvalidInput, match="lasts"):
        probe_video(p, VideoLimits(max_duration_s=1.0))
    with pytest.raises(InvalidInput, match="MB; the limit"):
        probe_video(p, VideoLimits(max_bytes=10))
    with pytest.raises(InvalidInput, match="pixels per frame"):
        probe_video(p, VideoLimits(max_pixels=100))


def test_bad_height(tmp_path):
    with pytest.raises(InvalidInput, match="height must be"):
        read_video(write_video(tmp_path / "a.mp4", 3), height=5)
