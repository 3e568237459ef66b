"""The filming check before stage 0: one frame, what the performer should change."""

from __future__ import annotations

import numpy as np
import pytest

from engine.errors import InvalidInput
from engine.io.video import read_video
from engine.stages.assessment import note_framing
from engine.stages.framing import (
    MIN_BODY_SHARE,
    check_framing,
    first_frame_problems,
    framing_of,
)
from tests.conftest import SHARED

SQUAT = SHARED / "data" / "real" / "squat_front_5fps.mp4"


def _standing(top: float = 0.1, bottom: float = 0.9) -> np.ndarray:
    """BlazePose-like landmarks (33, 2) of a person standing from ``top`` to ``bottom``."""
    lm = np.zeros((33, 2))
    lm[:, 0] = 0.5 + np.linspace(-0.1, 0.1, 33)
    lm[:, 1] = np.linspace(top, bottom, 33)
    lm[[0, 7, 8], 1] = top  # head
    lm[27:33, 1] = bottom  # ankles, heels, toes
    return lm


def test_a_whole_body_alone_and_large_is_fine():
    f = framing_of(_standing(), np.array([[0.5, 0.1]]))
    assert f.person_found and f.problems == () and f.people == 1
    assert f.body_share == pytest.approx(0.8)


def test_feet_below_the_picture_are_named():
    f = framing_of(_standing(0.3, 1.2), np.zeros((0, 2)))
    assert f.out_of_view == ("feet",)
    assert "Your feet are out of the picture" in f.problems[0]


def test_head_and_feet_out_together():
    f = framing_of(_standing(-0.2, 1.2), np.zeros((0, 2)))
    assert f.out_of_view == ("head", "feet")
    assert f.problems[0].startswith("Your head and feet are out of the picture")


def test_a_small_body_is_told_to_come_closer():
    f = framing_of(_standing(0.4, 0.4 + MIN_BODY_SHARE / 2), np.zeros((0, 2)))
    assert "come closer" in f.problems[0] and f.out_of_view == ()


def test_a_face_away_from_the_body_is_a_second_person():
    f = framing_of(_standing(), np.array([[0.5, 0.1], [0.95, 0.2]]))
    assert f.people == 2 and "Someone else is in view" in f.problems[-1]


def test_nobody_found():
    f = framing_of(None, np.zeros((0, 2)))
    assert not f.person_found and "No one was found" in f.problems[0]


def test_the_engine_checks_the_first_frame_again_in_pixels():
    px = _standing(0.3, 1.2) * np.array([640.0, 360.0])  # the feet below a 640 x 360 picture
    assert "Your feet are out" in first_frame_problems(px, True, 640, 360)[0]
    assert first_frame_problems(_standing() * np.array([640.0, 360.0]), True, 640, 360) == ()
    assert "No one was found" in first_frame_problems(px, False, 640, 360)[0]
    assert first_frame_problems(None, True, 640, 360) == ()  # a stage stored without landmarks


def test_the_result_says_what_the_first_frame_showed():
    doc = {"summary": {"messages": ["Segment 2 seems to be missing."]}}
    note_framing(doc, framing_of(_standing(0.3, 1.2), np.zeros((0, 2))).problems)
    first, framing = doc["summary"]["messages"]
    assert first == "Segment 2 seems to be missing."
    assert framing.startswith("At the start of the video, your feet are out of the picture")
    note_framing(doc, framing_of(None, np.zeros((0, 2))).problems)
    assert doc["summary"]["messages"][-1].startswith("No one was found in the first frame")


def test_the_model_on_a_real_clip_whole_cut_and_empty():
    frame = read_video(SQUAT, height=0, max_frames=2).frames[0]
    whole = check_framing(frame)
    assert whole.person_found and whole.problems == (), whole
    cut = check_framing(np.ascontiguousarray(frame[: int(0.6 * len(frame))]))
    assert "feet" in cut.out_of_view, cut
    empty = check_framing(np.full((240, 320, 3), 128, np.uint8))
    assert not empty.person_found


def test_the_perception_steps_landmarks_tell_the_same_as_the_upload_check():
    """The engine's check reads the landmarks the analysis already has, in working pixels."""
    from engine.stages.perception import perceive

    frames = read_video(SQUAT, height=240, max_frames=2).frames
    cut = np.ascontiguousarray(frames[:, : int(0.6 * frames.shape[1])])
    for video, feet_out in ((frames, False), (cut, True)):
        p = perceive(video)
        h, w = video.shape[1:3]
        problems = first_frame_problems(p.landmarks[0], bool(p.detected[0]), w, h)
        assert any("feet" in x for x in problems) == feet_out, problems


def test_not_a_picture_is_refused():
    with pytest.raises(InvalidInput, match="uint8 of shape"):
        check_framing(np.zeros((4, 4), np.uint8))
