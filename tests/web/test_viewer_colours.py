"""The 3D view's bone colours carry how sure each bone's error is."""

from __future__ import annotations

import numpy as np

from engine.report import error_colors
from web.viewer.scene import UNSURE_GREY, bone_colours


def test_a_bone_the_video_cannot_measure_is_paler_than_a_sure_one():
    errors = [20.0] * 16
    rng = [[19.0, 21.0]] * 16
    rng[3] = [2.0, 40.0]  # a bend in depth: anything from 2 to 40 deg explains the video
    c = bone_colours({"bone_errors_deg": errors, "bone_error_range_deg": rng})
    sure = error_colors(np.array(20.0))
    assert np.linalg.norm(c[0] - sure) < 0.05  # a 2-deg range barely fades it
    assert np.linalg.norm(c[3] - UNSURE_GREY) < np.linalg.norm(c[0] - UNSURE_GREY) - 0.2


def test_results_without_ranges_keep_the_error_colours():
    errors = np.linspace(0, 30, 16)
    np.testing.assert_allclose(bone_colours({"bone_errors_deg": errors}), error_colors(errors))
