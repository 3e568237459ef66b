"""A video of a set of repetitions: stages 1-2 and after see the first whole one only."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engine.io.bvh import load_reference
from engine.io.encode import write_video
from engine.io.result import validate_result
from engine.pipeline import Prepared, candidates, prepare, select
from engine.settings import Settings
from engine.synth import SynthSettings, synthesize

SQUAT = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "cmu" / "64_17.bvh"
#: stages 0-2 as configured, stage 3 small (test_pipeline.py's)
S = Settings.from_dict({
    "preset": "fast",
    "candidates": {"n_samples": 8, "n_iterations": 2, "refine_sweeps": 1, "n_candidates": 4},
})  # fmt: skip


@pytest.fixture(scope="module")
def two_squats(tmp_path_factory) -> tuple[Path, int]:
    """The CMU squat performed twice in a row (rest, squat, rest; twice), 10 fps, and the
    frames one performance takes."""
    if not SQUAT.exists():
        pytest.skip("needs ../shared/data/cmu/64_17.bvh")
    synth = synthesize(
        load_reference(SQUAT),
        settings=SynthSettings(fps=10.0, warp_strength=0.0, n_wrong=0, noise_sigma=1.0),
        rng=np.random.default_rng(5),
    )
    folder = tmp_path_factory.mktemp("set")
    video = folder / "two_squats.mp4"
    write_video(video, np.concatenate([synth.frames, synth.frames]), 10.0)
    write_video(folder / "one_squat.mp4", synth.frames, 10.0)
    return video, len(synth.frames)


@pytest.fixture(scope="module")
def cut(two_squats) -> Prepared:
    return prepare(SQUAT, two_squats[0], S)


def test_the_first_of_two_performances_is_analysed_and_both_are_listed(
    two_squats, cut
) -> None:
    video, one = two_squats
    p = cut
    reps = p.repetitions
    assert len(reps) == 2
    assert [r["analysed"] for r in reps] == [True, False]
    first, second = reps
    # the first covers the first performance, with rest around it, and stops before the
    # second's squat; the second lies in the second half
    assert first["start"] == p.video.offset and first["end"] - first["start"] == p.n_frames
    assert first["start"] <= 0.25 * one and 0.8 * one <= first["end"] <= 1.3 * one
    assert second["start"] >= first["end"] and second["end"] >= 1.6 * one
    assert second["start_s"] == pytest.approx(second["start"] / 10.0, abs=0.01)
    # stage 2 saw those frames only: its keypoints and regions are the cut's
    assert p.keypoints is not None and len(p.keypoints) == p.n_frames
    assert len(p.silhouettes) == p.n_frames and len(p.flags) == p.n_frames
    assert p.video.file_frames == 2 * one


def test_frames_the_user_chose_are_analysed_as_they_are(two_squats) -> None:
    video, one = two_squats
    p = prepare(SQUAT, video, S, frames=(0, 2 * one))
    assert p.repetitions == () and p.n_frames == 2 * one and p.video.offset == 0


def test_one_performance_is_left_whole(two_squats) -> None:
    video, one = two_squats
    p = prepare(SQUAT, video.with_name("one_squat.mp4"), S)
    assert p.repetitions == () and p.n_frames == one and p.video.offset == 0


def test_the_result_counts_the_files_frames_and_names_the_repetitions(cut) -> None:
    doc = select(cut, [candidates(cut, r, S) for r in cut.chunks(2)], S)
    validate_result(doc)
    a = cut.video.offset
    assert doc["video"]["first_frame"] == a == doc["frames"][0]["t"]
    assert [f["t"] for f in doc["frames"]] == list(range(a, a + cut.n_frames))
    assert doc["video"]["frames"] == cut.video.file_frames
    assert all(a <= s["performer_start"] <= s["performer_end"] < a + cut.n_frames
               for s in doc["segments"])  # fmt: skip
    reps = doc["summary"]["repetitions"]
    assert [r["analysed"] for r in reps] == [True, False]
    assert doc["summary"]["messages"][0].startswith("The video holds 2 whole repetitions")
