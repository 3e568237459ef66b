"""BVH limits (issue 26 item 2): a file over them is refused while it is read, before its
frames are stored, and memory follows the lines a file holds, never its header."""

from __future__ import annotations

import time
import tracemalloc
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from engine.body.skeleton import JOINTS
from engine.errors import InvalidInput
from engine.io.bvh import BvhLimits, bvh_forward_kinematics, load_reference, read_bvh
from engine.io.bvh.load import _mapped_positions
from tests.conftest import CMU

CMU_FILES = sorted(CMU.glob("*.bvh"))


def bvh_text(
    frames: int, lines: int | None = None, *, joints: int = 17, frame_time: float = 1 / 60,
    line: str = "0",
) -> str:  # fmt: skip
    """Our 17 joints (then ``x<k>``) hanging off the root, one Yrotation channel on the
    root, a header announcing ``frames`` and ``lines`` frame lines (``frames`` by default);
    a short line repeated, as in a BVH bomb."""
    names = [*JOINTS, *(f"x{k}" for k in range(joints - len(JOINTS)))][:joints]
    out = ["HIERARCHY", f"ROOT {names[0]}", "{", "OFFSET 0 0 0", "CHANNELS 1 Yrotation"]
    for k, n in enumerate(names[1:]):
        out += [f"JOINT {n}", "{", f"OFFSET {0.1 * (k % 5)} {0.1 * k} 0", "CHANNELS 0", "}"]
    out += ["}", "MOTION", f"Frames: {frames}", f"Frame Time: {frame_time!r}"]
    return "\n".join(out) + "\n" + (line + "\n") * (frames if lines is None else lines)


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "ref.bvh"
    p.write_text(text)
    return p


def measured(fn: Callable[[], object]) -> tuple[BaseException | None, float, float]:
    """The exception ``fn`` raised (None if none), seconds taken and peak MiB allocated."""
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        fn()
        exc = None
    except BaseException as e:  # noqa: BLE001 - returned to the test
        exc = e
    seconds = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    return exc, seconds, peak


# ------------------------------------------------------------------- refusals


def test_a_header_over_the_frame_limit_is_refused_before_any_frame_is_read(tmp_path):
    p = write(tmp_path, bvh_text(1_000_000))  # 2 MB: the MemoryError
    exc, seconds, peak = measured(lambda: read_bvh(p, BvhLimits()))
    assert isinstance(exc, InvalidInput)
    assert "has 1000000 frames; at most 36000 are accepted" in str(exc)
    assert seconds < 0.5 and peak < 2, (seconds, peak)
    # the header alone decides: three frame lines are refused with the same words
    with pytest.raises(InvalidInput, match="has 1000000 frames; at most 36000"):
        read_bvh(write(tmp_path, bvh_text(1_000_000, 3)), BvhLimits())


def test_a_header_that_understates_its_frames_cannot_carry_more_lines(tmp_path):
    p = write(tmp_path, bvh_text(10, 100_000))
    exc, seconds, peak = measured(lambda: read_bvh(p, BvhLimits()))
    assert isinstance(exc, InvalidInput)
    assert "more than 36000 frame lines (its header announces 10 frames)" in str(exc)
    assert seconds < 0.5 and peak < 2, (seconds, peak)
    # below the limit, lines after the announced frames are ignored, as they always were
    assert read_bvh(write(tmp_path, bvh_text(10, 36_000)), BvhLimits()).frames == 10
    assert read_bvh(p).frames == 10


def test_too_many_joints_are_refused_as_the_hierarchy_is_read(tmp_path):
    assert len(read_bvh(write(tmp_path, bvh_text(2, joints=256)), BvhLimits()).names) == 256
    with pytest.raises(InvalidInput, match="more than 256 joints .*at most 256 are accepted"):
        read_bvh(write(tmp_path, bvh_text(2, joints=257)), BvhLimits())
    # end sites are nodes too
    end_site = "CHANNELS 0\nEnd Site\n{\nOFFSET 0 0 0\n}\n}"
    text = bvh_text(2, joints=20).replace("CHANNELS 0\n}", end_site, 1)
    with pytest.raises(InvalidInput, match="more than 20 joints"):
        read_bvh(write(tmp_path, text), BvhLimits(max_joints=20))


def test_a_motion_longer_than_the_duration_limit_is_refused(tmp_path):
    limits = BvhLimits(max_duration_s=1.0)
    assert read_bvh(write(tmp_path, bvh_text(101, frame_time=0.01)), limits).frames == 101
    with pytest.raises(InvalidInput, match=r"lasts 1\.0 s \(102 frames at 100 fps\); at most 1 s"):
        read_bvh(write(tmp_path, bvh_text(102, frame_time=0.01)), limits)
    # 10 minutes at 60 fps, Frame Time rounded in the file as exporters do, is accepted
    assert read_bvh(write(tmp_path, bvh_text(36_000, frame_time=0.0166667)), BvhLimits()).frames


def test_too_many_channels_are_refused_on_their_count(tmp_path):
    text = bvh_text(1).replace("CHANNELS 1 Yrotation", "CHANNELS 7 " + "Yrotation " * 7)
    with pytest.raises(InvalidInput, match="more than 6 channels; at most 6 are accepted"):
        read_bvh(write(tmp_path, text), BvhLimits(max_channels=6))


def test_load_reference_passes_its_limits_down(tmp_path):
    p = write(tmp_path, bvh_text(50))
    assert load_reference(p, units_to_m=1.0).motion.frames == 50
    with pytest.raises(InvalidInput, match="has 50 frames; at most 49 are accepted"):
        load_reference(p, units_to_m=1.0, limits=BvhLimits(max_frames=49))


@pytest.mark.parametrize("field", ["max_frames", "max_duration_s", "max_joints", "max_channels"])
def test_limits_must_be_positive(field):
    with pytest.raises(ValueError, match=field):
        BvhLimits(**{field: 0})


# ------------------------------------------------- memory follows the lines read


def test_without_limits_a_lying_header_allocates_only_what_the_lines_hold(tmp_path):
    p = write(tmp_path, bvh_text(10**9, 3))  # 10^9 frames would be 8 GB up front
    exc, seconds, peak = measured(lambda: read_bvh(p))
    assert isinstance(exc, InvalidInput) and "only 3 frame lines follow" in str(exc)
    assert seconds < 0.5 and peak < 2, (seconds, peak)


def test_a_huge_frame_line_is_refused_without_splitting_it(tmp_path):
    p = write(tmp_path, bvh_text(1, line="10 " * 1_000_000))  # 3 MB, ~60 MB as a word list
    exc, _, peak = measured(lambda: read_bvh(p))
    assert isinstance(exc, InvalidInput)
    assert "frame 0 has 1000000 values, the hierarchy has 1 channels" in str(exc)
    assert peak < 20, peak


# ----------------------------------------------------- normal files, as before


@pytest.fixture(params=[p.name for p in CMU_FILES] or ["missing"])
def cmu_file(request) -> Path:
    if not CMU_FILES:
        pytest.skip("../shared/data/cmu is not beside the clone")
    return CMU / request.param


def test_cmu_files_parse_as_their_text_says(cmu_file):
    """Every frame line, parsed on its own by NumPy, equals the parsed values bit for bit;
    the limits change nothing for a file within them."""
    b = read_bvh(cmu_file)
    lines = cmu_file.read_text().splitlines()
    at = next(i for i, s in enumerate(lines) if s.startswith("Frame Time:"))
    rows = [s for s in lines[at + 1 :] if s.strip()]
    assert b.frames == int(lines[at - 1].split()[1]) == len(rows)
    assert b.frame_time == float(lines[at].split(":")[1])
    np.testing.assert_array_equal(b.values, np.loadtxt(rows, ndmin=2))
    assert len(b.names) == 38 and b.values.shape[1] == 96  # CMU: 31 joints, 7 end sites
    limited = read_bvh(cmu_file, BvhLimits())
    np.testing.assert_array_equal(limited.values, b.values)
    assert (limited.names, limited.channels) == (b.names, b.channels)
    np.testing.assert_array_equal(limited.offsets, b.offsets)


def test_long_files_go_through_kinematics_in_chunks_with_the_same_result(cmu_file):
    b = read_bvh(cmu_file)
    long = replace(b, values=np.concatenate([b.values] * 12))  # > one chunk of 3449 frames
    idx = np.arange(0, len(b.names), 3)
    np.testing.assert_array_equal(
        _mapped_positions(long, idx), bvh_forward_kinematics(long)[:, idx]
    )
