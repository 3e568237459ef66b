"""References from several takes in the browser: the upload, the card, and an analysis
page that says where the performer is within or outside the expert's own range."""

from __future__ import annotations

import json

import pytest

from tests.browser.conftest import COACH, sign_in
from tests.browser.test_pages_browser import wait_results
from tests.conftest import CMU

pytestmark = pytest.mark.browser


def test_a_coach_builds_a_reference_from_two_takes(server, browser, shots):
    for n in ("64_29", "64_30"):
        if not (CMU / f"{n}.bvh").exists():
            pytest.skip("../shared/data/cmu is not beside the clone")
    page = browser.new_context(viewport={"width": 1280, "height": 900}).new_page()
    sign_in(page, server.url, COACH[0], COACH[1], next_path="/references")
    page.wait_for_selector("#ref-list")
    before = page.locator(".ref-card").count()
    page.locator("#ref-upload").get_by_label("Name", exact=True).fill("Bend, two takes")
    page.get_by_label("BVH file").set_input_files([str(CMU / "64_29.bvh"), str(CMU / "64_30.bvh")])
    page.get_by_role("button", name="Upload reference").click()
    page.locator("#ref-done").wait_for(timeout=60_000)
    assert "from 2 takes" in page.locator("#ref-done").inner_text()
    page.wait_for_function(f"() => document.querySelectorAll('.ref-card').length === {before + 1}")
    card = page.locator(".ref-card", has_text="Bend, two takes")
    assert "Built from 2 takes (64_29, 64_30)" in card.inner_text()
    plot = card.locator("img.takes-plot")
    page.wait_for_function(
        "(img) => img.complete && img.naturalWidth > 300", arg=plot.element_handle()
    )
    card.get_by_text("The expert's own variation per bone").click()
    assert card.locator("table.spread tbody tr").count() == 16
    page.screenshot(path=str(shots / "reference-from-takes.png"), full_page=True)


def test_the_analysis_page_shows_the_experts_range(server, browser, clip, clip_result, shots):
    result = json.loads(json.dumps(clip_result))
    for f in result["frames"]:
        f["expert_spread_deg"] = 6.0
        f["bone_z"] = [e / 6.0 for e in f["bone_errors_deg"]]
        f["outside_expert_range"] = max(f["bone_z"]) > 3
    for j, s in enumerate(result["segments"]):
        s["within_expert_range"] = j != 0
        s["outside_bones"] = [] if j else ["r_shoulder->r_elbow"]
        s["bone_mean_z"] = [e / 6.0 for e in s["bone_mean_errors_deg"]]
    aid = server.add_done_analysis("pat", clip, result)
    page = browser.new_context(viewport={"width": 1280, "height": 1000}).new_page()
    sign_in(page, server.url, "pat@example.com", next_path=f"/analyses/{aid}")
    wait_results(page)
    assert page.locator("#plot-svg polygon.expert-band").count() == 1
    assert "expert's own variation" in page.locator("#plot-svg").inner_html()
    cards = page.locator(".seg-card")
    assert "outside the expert's range at right upper arm" in cards.first.inner_text()
    if cards.count() > 1:
        assert "within the expert's range" in cards.nth(1).inner_text()
    page.screenshot(path=str(shots / "analysis-expert-range.png"), full_page=True)


def test_the_expert_drawn_over_the_video_slow_motion_and_loop(
    server, browser, clip, clip_result, shots
):
    """The 'Expert' toggle draws the expert's skeleton where the performer stands; the speed
    select slows the video; the segment loop brings playback back to the segment's start."""
    import numpy as np

    assert all(f.get("expert_joints_2d") for f in clip_result["frames"])
    aid = server.add_done_analysis("pat", clip, clip_result)
    page = browser.new_context(viewport={"width": 1280, "height": 1000}).new_page()
    sign_in(page, server.url, "pat@example.com", next_path=f"/analyses/{aid}")
    wait_results(page)

    def ghost_pixels() -> int:
        data = page.evaluate("""() => { const c = document.querySelector('#overlay');
            return Array.from(c.getContext('2d').getImageData(0, 0, c.width, c.height).data); }""")
        rgba = np.asarray(data, np.int32).reshape(-1, 4)
        return int((np.abs(rgba[:, :3] - [110, 130, 200]).max(1) <= 25).sum())

    assert page.locator("#expert-toggle").is_visible()
    page.get_by_role("checkbox", name="Skeleton").uncheck()
    assert ghost_pixels() == 0
    page.get_by_role("checkbox", name="Expert").check()
    assert ghost_pixels() > 50
    # drawn where the engine projects the expert (the engine's own test checks that this
    # lands on the performer's true joints): the ghost's colour at its hips, knees and head
    k = int(page.evaluate("document.getElementById('analysis').dataset.frame"))
    for j in (0, 2, 5, 16):
        u, v = clip_result["frames"][k]["expert_joints_2d"][j]
        px = page.evaluate(
            "([u, v]) => Array.from(document.getElementById('overlay').getContext('2d')"
            ".getImageData(Math.round(u), Math.round(v), 1, 1).data)", [u, v],
        )  # fmt: skip
        assert np.abs(np.asarray(px[:3]) - [110, 130, 200]).max() <= 40, (j, px)
    assert page.locator("#legend-expert").is_visible()
    page.screenshot(path=str(shots / "analysis-expert-ghost.png"), full_page=True)
    page.get_by_label("Playback speed").select_option("0.25")
    assert page.evaluate("() => document.getElementById('video').playbackRate") == 0.25
    first = clip_result["segments"][0]
    page.get_by_role("checkbox", name="Loop segment").check()
    page.locator(".seg-card").first.click()
    page.evaluate("() => { const v = document.getElementById('video'); v.playbackRate = 4; "
                  "v.play(); }")  # fmt: skip
    fps = clip_result["video"]["fps"]
    end_s = (first["performer_end"] + 1) / fps
    page.wait_for_timeout(int(3000 * end_s / 4) + 1500)
    t = page.evaluate("() => document.getElementById('video').currentTime")
    assert t <= end_s + 0.5 / fps, f"played on past the looped segment: {t:.2f} s"


def test_side_by_side_stays_in_step_when_paused_and_stepped(server, browser, clip, clip_result,
                                                            shots):  # fmt: skip
    """'Side by side' draws the expert, in the performer's camera, beside the video; frame
    stepping and pausing keep both at one frame: the head drawn where that frame puts it."""
    import numpy as np

    aid = server.add_done_analysis("pat", clip, clip_result)
    page = browser.new_context(viewport={"width": 1280, "height": 1000}).new_page()
    sign_in(page, server.url, "pat@example.com", next_path=f"/analyses/{aid}")
    wait_results(page)
    page.get_by_role("checkbox", name="Side by side").check()
    assert page.locator("#side-box").is_visible()

    def head_drawn(k: int) -> bool:
        """The expert's head of result frame k is drawn on the side canvas (and the one of
        another frame, far from it, is not)."""
        u, v = clip_result["frames"][k]["expert_joints_2d"][16]
        px = page.evaluate(
            "([u, v]) => Array.from(document.getElementById('side-canvas').getContext('2d')"
            ".getImageData(Math.round(u), Math.round(v), 1, 1).data)", [u, v],
        )  # fmt: skip
        return bool(np.abs(np.asarray(px[:3]) - [110, 130, 200]).max() <= 30)

    page.evaluate("() => document.getElementById('video').pause()")
    for _ in range(4):
        k = int(page.evaluate("document.getElementById('analysis').dataset.frame"))
        assert page.get_attribute("#side-canvas", "data-frame") == str(k)
        assert head_drawn(k), k
        page.get_by_role("button", name="Next frame").click()
        page.wait_for_function(
            f"() => document.getElementById('analysis').dataset.frame === '{k + 1}'"
        )
    page.locator(".video-wrap").screenshot(path=str(shots / "analysis-side-by-side.png"))
    page.get_by_role("button", name="Previous frame").click()
    k = int(page.evaluate("document.getElementById('analysis').dataset.frame"))
    assert page.get_attribute("#side-canvas", "data-frame") == str(k) and head_drawn(k)
