"""Video input judged by what the file holds, not by what its header claims (issue 26).

A header that understates the duration must not make the worker decode minutes of video
(memory is bounded by the limits), and a file cut short in transfer must be refused as
truncated instead of analysed as complete.
"""

from __future__ import annotations

import struct
import tracemalloc
from pathlib import Path

import av
import numpy as np
import pytest

from engine.errors import InvalidInput
from engine.io import video as video_io
from engine.io.video import VideoLimits, probe_video, read_video


def write_video(path: Path, n: int, w: int, h: int, *, noise: bool = False, **fmt: str) -> Path:
    """``n`` frames at 30 fps of a white square crossing black; ``noise`` makes each frame
    cost bytes (a cut file then keeps its index and loses frames) and picks MPEG-4 Part 2,
    which encodes it faster than x264."""
    rng = np.random.default_rng(0)
    codec, options = ("mpeg4", {}) if noise else ("libx264", {"preset": "ultrafast"})
    img = np.zeros((h, w, 3), np.uint8)
    with av.open(str(path), "w", options=fmt) as c:
        s = c.add_stream(codec, rate=30, options=options)
        s.width, s.height, s.pix_fmt = w, h, "yuv420p"
        for i in range(n):
            if noise:
                img = rng.integers(0, 40, (h, w, 3), dtype=np.uint8)
            else:
                img[:] = 0
            x = (i * 7) % (w - h // 4)
            img[h // 3 : h // 3 + h // 4, x : x + h // 4] = 255
            for p in s.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                c.mux(p)
        for p in s.encode():
            c.mux(p)
    return path


def claim_duration(mkv: Path, seconds: float) -> Path:
    """Rewrite the Matroska header's Duration element (ID 0x4489, float ms): the file keeps
    every frame but now says it lasts ``seconds``."""
    data = bytearray(mkv.read_bytes())
    i = data.find(b"\x44\x89")
    assert i > 0 and data[i + 2] == 0x88, "expected an 8-byte float Duration element"
    struct.pack_into(">d", data, i + 3, seconds * 1000.0)
    mkv.write_bytes(bytes(data))
    return mkv


def trusting_probe(path, limits=VideoLimits()):
    """The probe as it was: believe the header (no limit on what the file holds)."""
    return probe_video(path, VideoLimits(max_duration_s=1e9, max_frames=10**9, min_complete=0))


def peak_mb(fn) -> tuple[float, Exception | None]:
    """Peak traced memory (MB) while ``fn`` runs, and what it raised."""
    tracemalloc.start()
    try:
        fn()
        raised = None
    except InvalidInput as exc:
        raised = exc
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    return peak / 2**20, raised


@pytest.fixture(scope="module")
def lying(tmp_path_factory) -> Path:
    """10 s of 720p video whose header says 0.5 s (300 frames: 92 MB at 426 x 240)."""
    p = write_video(tmp_path_factory.mktemp("lying") / "lying.mkv", 300, 1280, 720)
    claim_duration(p, 0.5)
    with av.open(str(p)) as c:
        assert c.duration == pytest.approx(5e5, rel=0.01)  # the header lies
    return p


def test_probe_counts_what_the_file_holds(lying):
    with pytest.raises(InvalidInput, match=r"lasts more than 5 s \(its header says 0.5 s\)"):
        probe_video(lying, VideoLimits(max_duration_s=5.0))
    with pytest.raises(InvalidInput, match="more than 100 frames"):
        probe_video(lying, VideoLimits(max_frames=100))


def test_lying_header_is_refused_before_decoding(lying):
    peak, raised = peak_mb(lambda: read_video(lying, limits=VideoLimits(max_duration_s=5.0)))
    assert raised is not None and "lasts more than 5 s" in str(raised)
    assert peak < 10, f"{peak:.0f} MB traced"


def test_decoding_stops_at_the_limit_even_if_the_probe_believes_the_header(lying, monkeypatch):
    monkeypatch.setattr(video_io, "probe_video", trusting_probe)
    # 1 s is 31 frames of 426 x 240 x 3 (9 MB, in an array grown to 60); all 300 are 92 MB
    # (twice that once stacked), and 31 full-size 720p frames would be 86 MB
    peak, raised = peak_mb(lambda: read_video(lying, limits=VideoLimits(max_duration_s=1.0)))
    assert raised is not None and "lasts more than 1 s" in str(raised)
    assert peak < 50, f"{peak:.0f} MB traced"
    with pytest.raises(InvalidInput, match="more than 40 frames"):
        read_video(lying, limits=VideoLimits(max_frames=40))


def test_memory_is_the_scaled_frames_only(tmp_path):
    p = write_video(tmp_path / "a.mp4", 45, 1280, 720)
    peak, raised = peak_mb(lambda: read_video(p, height=240))
    assert raised is None
    # 13.2 MB of frames, held once: not twice (a list, then stacked), nor at 720p (119 MB);
    # one 720p frame (2.6 MB) at a time is decoded
    working = 45 * 240 * 426 * 3 / 2**20
    assert peak < working + 8, f"{peak:.0f} MB traced for {working:.0f} MB of frames"


@pytest.fixture
def faststart(tmp_path) -> Path:
    """A whole 60-frame mp4 with its index (moov) first, as phones and browsers write it."""
    return write_video(tmp_path / "whole.mp4", 60, 320, 240, noise=True, movflags="faststart")


def cut(path: Path, fraction: float) -> Path:
    out = path.with_name(f"cut-{fraction}.mp4")
    data = path.read_bytes()
    out.write_bytes(data[: int(len(data) * fraction)])
    return out


def test_whole_faststart_file_reads_every_frame(faststart):
    assert read_video(faststart).n_frames == 60


@pytest.mark.parametrize("fraction", [0.25, 0.6])
def test_truncated_faststart_mp4_is_refused(faststart, fraction):
    t = cut(faststart, fraction)
    with av.open(str(t)) as c:  # the index still announces every frame
        assert c.streams.video[0].frames == 60
    with pytest.raises(InvalidInput, match=r"truncated: \d+ of the 60 frames .* are in the file"):
        probe_video(t)
    with pytest.raises(InvalidInput, match="truncated"):
        read_video(t)


def test_decoder_refuses_a_truncated_file_the_probe_let_through(faststart, monkeypatch):
    t = cut(faststart, 0.25)
    monkeypatch.setattr(video_io, "probe_video", lambda path, limits: probe_video(faststart))
    with pytest.raises(InvalidInput, match=r"truncated: \d+ of the 60 frames .* could be decoded"):
        read_video(t)
