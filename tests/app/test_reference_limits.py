"""A BVH bomb does not take the API down (issue 26 item 2): a few hundred kilobytes
announcing 100 000 frames are refused with 422 from the header, in milliseconds and a few
megabytes, where they used to cost the API process 52 s and 0.9 GB."""

from __future__ import annotations

import time
import tracemalloc
from pathlib import Path

import pytest

from app.core import validation
from app.core.config import Settings
from engine.body.skeleton import JOINTS
from engine.errors import InvalidInput
from tests.app.conftest import SAMPLE_BVH, stored_files


def bomb(path: Path, frames: int, lines: int) -> Path:
    """Our 17 joints off the root, one channel, and ``lines`` lines "0": 2 bytes a frame."""
    out = ["HIERARCHY", f"ROOT {JOINTS[0]}", "{", "OFFSET 0 0 0", "CHANNELS 1 Yrotation"]
    for k, n in enumerate(JOINTS[1:]):
        out += [f"JOINT {n}", "{", f"OFFSET {0.1 * (k % 5)} {0.1 * k} 0", "CHANNELS 0", "}"]
    out += ["}", "MOTION", f"Frames: {frames}", "Frame Time: 0.0166667"]
    path.write_text("\n".join(out) + "\n" + "0\n" * lines)
    return path


@pytest.mark.parametrize(
    ("frames", "says"),
    [
        (100_000, "has 100000 frames; at most 36000 are accepted"),
        (10, "more than 36000 frame lines (its header announces 10 frames)"),  # it lies
    ],
)
def test_a_bvh_bomb_is_refused_at_once(client, club, settings, tmp_path, frames, says):
    path = bomb(tmp_path / "bomb.bvh", frames, 100_000)
    assert path.stat().st_size < 250_000
    t0 = time.perf_counter()
    with open(path, "rb") as f:
        r = client.post("/api/v1/references", headers=club.headers, files={"file": ("b.bvh", f)})
    seconds = time.perf_counter() - t0
    assert r.status_code == 422, r.text
    assert r.json()["error"]["code"] == "invalid_reference"
    assert says in r.json()["error"]["message"]
    assert seconds < 1.0, seconds
    assert client.get("/api/v1/references", headers=club.headers).json()["items"] == []
    assert stored_files(settings) == []


@pytest.mark.parametrize("frames", [100_000, 1_000_000])
def test_inspecting_a_bomb_allocates_a_few_megabytes(settings, tmp_path, frames):
    path = bomb(tmp_path / "bomb.bvh", frames, frames)  # 200 KB and 2 MB
    tracemalloc.start()
    try:
        with pytest.raises(InvalidInput, match=f"has {frames} frames"):
            validation.inspect_reference(path, None, settings)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 50 * 2**20, peak / 2**20


def test_the_limits_come_from_the_settings(tmp_path):
    if not SAMPLE_BVH.exists():
        pytest.skip("../shared/data/cmu is not beside the clone")
    assert validation.inspect_reference(SAMPLE_BVH, None, Settings())["frames"] == 580
    for over, says in [
        ({"max_reference_frames": 579}, "has 580 frames; at most 579 are accepted"),
        ({"max_reference_duration_s": 4.0}, r"lasts 4\.8 s \(580 frames at 120 fps\)"),
        ({"max_reference_joints": 37}, "more than 37 joints"),
    ]:
        with pytest.raises(InvalidInput, match=says):
            validation.inspect_reference(SAMPLE_BVH, None, Settings(**over))
    # a file already on the server (demo, migrations) is read without limits
    frames = validation.inspect_reference(SAMPLE_BVH, None)["frames"]
    assert frames == 580
