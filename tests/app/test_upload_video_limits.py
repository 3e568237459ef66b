"""The upload refuses what the worker could not analyse honestly (issue 26 items 6 and 7):
a file cut short in transfer, and a file whose header understates its length."""

from __future__ import annotations

import struct
from pathlib import Path

import av
import numpy as np

from app.models import Analysis
from tests.app.conftest import upload


def write_video(path: Path, n: int, **fmt: str) -> Path:
    """``n`` noisy 320 x 240 frames at 30 fps (noise: each frame costs bytes)."""
    rng = np.random.default_rng(0)
    with av.open(str(path), "w", options=fmt) as c:
        s = c.add_stream("mpeg4", rate=30)
        s.width, s.height, s.pix_fmt = 320, 240, "yuv420p"
        for _ in range(n):
            img = rng.integers(0, 255, (240, 320, 3), dtype=np.uint8)
            for p in s.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                c.mux(p)
        for p in s.encode():
            c.mux(p)
    return path


def _refused(app, queue, response, *words: str) -> None:
    assert response.status_code == 422, response.text
    error = response.json()["error"]
    assert error["code"] == "invalid_video"
    for w in words:
        assert w in error["message"]
    with app.state.sessionmaker() as s:
        assert s.query(Analysis).count() == 0
    assert queue.jobs == []


def test_truncated_faststart_mp4_is_422_saying_so(client, app, club_ref, queue, tmp_path):
    whole = write_video(tmp_path / "whole.mp4", 60, movflags="faststart")
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size // 4])
    r = upload(client, club_ref, cut)
    _refused(app, queue, r, "truncated", "of the 60 frames", "upload the whole file")
    assert str(tmp_path) not in r.json()["error"]["message"]


def test_header_that_understates_the_duration_is_422(
    client, app, club_ref, queue, settings, tmp_path
):
    settings.max_video_duration_s = 2.0
    mkv = write_video(tmp_path / "long.mkv", 120)  # 4 s
    data = bytearray(mkv.read_bytes())
    i = data.find(b"\x44\x89")  # Matroska Duration (float ms): now says 1 s
    assert data[i + 2] == 0x88
    struct.pack_into(">d", data, i + 3, 1000.0)
    mkv.write_bytes(bytes(data))
    r = upload(client, club_ref, mkv)
    _refused(app, queue, r, "lasts more than 2 s", "its header says 1.0 s")
