"""Provisional results: stage 4 on the segments whose frames stage 3 has finished.

Stage 3 is most of an analysis' time (issue 25), and its chunks finish one by one. Stage 2's
C(t') already says where each reference segment lies in the video, so once the chunks from
the first frame onwards cover whole segments, stage 4 can run on those alone and the coach
sees the first segments' errors before the last chunk is done. Each segment's result is the
same computation as the final one on a shorter video: only the boundary after the last
covered segment is not searched (it is the end of that shorter video), so the final result
may move it by a frame or two and change those segments' figures a little.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from engine.pipeline import select
from engine.settings import Settings
from engine.stage_outputs import CandidateChunk, Prepared
from engine.types import Segments


def finished_prefix(prepared: Prepared, chunks: Sequence[CandidateChunk]) -> int:
    """How many video frames from the first one have candidates in ``chunks``."""
    done = np.zeros(prepared.n_frames, dtype=bool)
    for c in chunks:
        done[np.asarray(c.frames, dtype=int)] = True
    return int(np.argmin(done)) if not done.all() else prepared.n_frames


def covered_segments(prepared: Prepared, n_done: int) -> tuple[int, int]:
    """(k, n): the first k reference segments lie wholly in the first ``n_done`` video frames
    by stage 2's C(t'), and they end at video frame n - 1 (where C reaches the start of
    segment k + 1). (0, 0) when not even the first segment is covered. The last segment
    counts only when every frame is done: it runs to the video's end."""
    starts = prepared.segments.starts
    C = np.asarray(prepared.C)
    k, n = 0, 0
    for i, next_start in enumerate(starts[1:]):
        reached = np.flatnonzero(C >= next_start)
        # the boundary frame itself must be done: it is the shorter video's last frame
        if len(reached) == 0 or int(reached[0]) >= n_done:
            break
        k, n = i + 1, int(reached[0]) + 1
    if n_done >= prepared.n_frames:
        return len(starts), prepared.n_frames
    return k, n


def select_provisional(
    prepared: Prepared, chunks: Sequence[CandidateChunk], settings: Settings | None = None
) -> dict | None:
    """The result document of the whole segments ``chunks`` cover from the first frame, with
    a ``provisional`` entry (frames and segments covered, of how many); None when they cover
    no whole segment, or every frame (then the final result is due, not a provisional one).
    """
    k, n = covered_segments(prepared, finished_prefix(prepared, chunks))
    n_segments = len(prepared.segments.starts)
    if k == 0 or n >= prepared.n_frames:
        return None
    seg = prepared.segments
    head = prepared.head(n, Segments(seg.starts[:k], int(seg.starts[k]), seg.names[:k]))
    doc = select(head, [c for c in (_cut(c, n) for c in chunks) if c is not None], settings)
    doc["provisional"] = {
        "frames": n, "video_frames": prepared.n_frames,
        "segments": k, "reference_segments": n_segments,
    }  # fmt: skip
    return doc


def _cut(chunk: CandidateChunk, n_frames: int) -> CandidateChunk | None:
    """``chunk``'s frames below ``n_frames``; None when it has none."""
    keep = np.flatnonzero(np.asarray(chunk.frames) < n_frames)
    if len(keep) == 0:
        return None
    pick = [int(i) for i in keep]
    return CandidateChunk(
        frames=np.asarray(chunk.frames)[keep], candidates=[chunk.candidates[i] for i in pick],
        d_s=[chunk.d_s[i] for i in pick], flags=tuple(chunk.flags[i] for i in pick),
        seconds=chunk.seconds,
    )  # fmt: skip
