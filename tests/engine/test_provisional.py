"""Provisional results: stage 4 on the whole segments whose stage-3 chunks are done."""

from __future__ import annotations

import numpy as np
import pytest

from engine.errors import InvalidInput
from engine.io.result import validate_result
from engine.pipeline import Prepared, candidates, prepare, select
from engine.provisional import covered_segments, finished_prefix, select_provisional
from engine.reference.domain import parse_domain
from engine.types import Segments
from tests.engine.test_pipeline import S, case_dir  # noqa: F401 - the module's case fixture

#: Two reference segments (the swing's down and up halves), so one can finish first.
DOMAIN = {"segments": [0, 30], "segment_names": ["down", "up"]}


@pytest.fixture(scope="module")
def two_segments(case_dir) -> Prepared:  # noqa: F811
    return prepare(case_dir["reference"], case_dir["video"], S, domain=parse_domain(DOMAIN))


@pytest.fixture(scope="module")
def chunks(two_segments):
    return [candidates(two_segments, r, S) for r in two_segments.chunks(4)]


def _first_boundary(p: Prepared) -> int:
    """The video frame where stage 2's C reaches the second segment."""
    return int(np.flatnonzero(p.C >= p.segments.starts[1])[0])


def test_a_segment_counts_once_its_boundary_frame_is_done(two_segments) -> None:
    b = _first_boundary(two_segments)
    assert 0 < b < two_segments.n_frames - 1
    assert covered_segments(two_segments, b) == (0, 0)
    assert covered_segments(two_segments, b + 1) == (1, b + 1)
    # the last segment runs to the video's end: it counts only with every frame
    assert covered_segments(two_segments, two_segments.n_frames - 1) == (1, b + 1)
    assert covered_segments(two_segments, two_segments.n_frames) == (2, two_segments.n_frames)


def test_only_chunks_from_the_first_frame_on_count(two_segments, chunks) -> None:
    assert finished_prefix(two_segments, chunks[1:]) == 0
    assert finished_prefix(two_segments, [chunks[0], chunks[2]]) == len(chunks[0].frames)
    assert finished_prefix(two_segments, chunks) == two_segments.n_frames


def test_the_first_segment_is_reported_before_the_last_chunk(two_segments, chunks) -> None:
    b = _first_boundary(two_segments)
    first = [c for c in chunks if int(c.frames[0]) <= b]
    doc = select_provisional(two_segments, first, S)
    assert doc is not None
    validate_result(doc)
    assert doc["provisional"] == {"frames": b + 1, "video_frames": two_segments.n_frames,
                                  "segments": 1, "reference_segments": 2}  # fmt: skip
    assert [f["t"] for f in doc["frames"]] == list(range(b + 1))
    (seg,) = doc["segments"]
    assert (seg["performer_start"], seg["performer_end"]) == (0, b)
    assert (seg["reference_start"], seg["reference_end"], seg["name"]) == (0, 30, "down")
    # The same candidates and the same stage 4 as the final result, on a shorter video.
    final = select(two_segments, chunks, S)
    assert [f["selected"] for f in doc["frames"][:b]] == [
        f["selected"] for f in final["frames"][:b]
    ]


def test_nothing_provisional_before_a_segment_or_once_everything_is_done(
    two_segments, chunks
) -> None:
    b = _first_boundary(two_segments)
    before = [c for c in chunks if int(c.frames[-1]) < b]
    assert select_provisional(two_segments, before, S) is None
    assert select_provisional(two_segments, chunks, S) is None


def test_a_head_outside_the_video_is_refused(two_segments) -> None:
    seg = Segments((0,), 30)
    for bad in (0, two_segments.n_frames + 1):
        with pytest.raises(InvalidInput, match="n_frames"):
            two_segments.head(bad, seg)
