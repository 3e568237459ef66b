"""The upload page's filming check through the API: one frame in, what to change out."""

from __future__ import annotations

import cv2
import numpy as np

from engine.io.video import read_video
from tests.engine.stages.test_framing import SQUAT
from tests.web.test_pages import env, sign_in  # noqa: F401 - env is a fixture


def _jpeg(rgb: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    assert ok
    return buf.tobytes()


def _post(client, data: bytes, name: str = "first-frame.jpg"):
    return client.post("/api/v1/framing", files={"frame": (name, data, "image/jpeg")})


def test_the_first_frame_says_what_to_change(env):  # noqa: F811
    _, client, *_ = env
    frame = read_video(SQUAT, height=0, max_frames=2).frames[0]
    assert _post(client, _jpeg(frame)).status_code == 401  # signed-in users only
    sign_in(client, "p@a.org")
    whole = _post(client, _jpeg(frame))
    assert whole.status_code == 200, whole.text
    assert whole.json()["person_found"] and whole.json()["problems"] == []
    cut = _post(client, _jpeg(np.ascontiguousarray(frame[: int(0.6 * len(frame))]))).json()
    assert cut["out_of_view"] == ["feet"] and "feet are out of the picture" in cut["problems"][0]


def test_what_is_not_one_frame_is_refused(env):  # noqa: F811
    _, client, *_ = env
    sign_in(client, "p@a.org")
    bad = _post(client, b"not a picture")
    assert bad.status_code == 422 and bad.json()["error"]["code"] == "invalid_image"
    huge = _post(client, b"\xff" * 4_000_001)
    assert huge.status_code == 413
    wide = _post(client, _jpeg(np.zeros((8, 5000, 3), np.uint8)))
    assert wide.status_code == 422 and "4096" in wide.json()["error"]["message"]
