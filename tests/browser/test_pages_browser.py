"""The browser experience end to end: real app, real worker, Debian Chromium."""

from __future__ import annotations

import csv
import io
import json
import re
import time

import numpy as np
import pytest
from playwright.sync_api import TimeoutError as PlaywrightTimeout

from app.core import media
from tests.browser.conftest import COACH, analysis_diagnosis, open_done_analysis, sign_in

pytestmark = pytest.mark.browser


def _pixels_of(png: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def canvas_colours(page, selector: str) -> tuple[int, int]:
    """Counts of red-ish and green-ish pixels of a canvas (its own pixels, not the page)."""
    data = page.evaluate(
        """(sel) => { const c = document.querySelector(sel);
             return Array.from(c.getContext('2d').getImageData(0, 0, c.width, c.height).data); }""",
        selector,
    )
    rgba = np.asarray(data, np.int32).reshape(-1, 4)
    seen = rgba[rgba[:, 3] > 200]
    red = (seen[:, 0] > 180) & (seen[:, 1] < 110) & (seen[:, 2] < 80)
    green = (seen[:, 1] > 180) & (seen[:, 0] < 150) & (seen[:, 2] < 80)
    return int(red.sum()), int(green.sum())


def amber_pixels(page) -> int:
    """Pixels of the overlay canvas in the misfit amber #fab005."""
    data = page.evaluate(
        """() => { const c = document.querySelector('#overlay');
             return Array.from(c.getContext('2d').getImageData(0, 0, c.width, c.height).data); }"""
    )
    rgba = np.asarray(data, np.int32).reshape(-1, 4)
    near = np.abs(rgba[:, :3] - np.array([250, 176, 5])).max(1) <= 6
    return int((near & (rgba[:, 3] > 200)).sum())


def most_colourful_frame(result: dict) -> int:
    """A frame with a red bone (>= 36 deg on common.js's ramp, red at 45) and a green one
    (<= 13 deg), as red as possible: what ``canvas_colours`` counts."""
    e = np.array([f["bone_errors_deg"] for f in result["frames"]])
    both = (e.max(1) >= 36.0) & (e.min(1) <= 13.0)
    assert both.any(), "the clip's analysis has no frame with both a red and a green bone"
    return int(np.argmax(np.where(both, e.max(1), -np.inf)))


def go_to_frame(page, frame: int) -> None:
    page.get_by_role("slider", name="Timeline: press left and right to move a frame").focus()
    page.keyboard.press("Home")
    for _ in range(frame):
        page.keyboard.press("ArrowRight")
    page.wait_for_function(f"() => document.getElementById('analysis').dataset.frame === '{frame}'")


def wait_results(page, timeout_ms: float = 60_000) -> None:
    page.wait_for_selector("#analysis[data-ready=true]", timeout=timeout_ms)
    page.wait_for_function(
        "() => document.getElementById('video').readyState >= 2", timeout=timeout_ms
    )


def test_upload_through_the_page_runs_to_results(server, browser, clip, shots):
    ctx = browser.new_context(viewport={"width": 1280, "height": 900})
    page = ctx.new_page()
    sign_in(page, server.url, "pat@example.com")
    assert page.url.endswith("/analyses")  # a performer's home: their attempts
    page.get_by_role("navigation", name="Main").get_by_role("link", name="New analysis").click()
    page.wait_for_url("**/upload")
    page.wait_for_selector(".ref-option canvas[data-ready=true]")
    # the demo reference's segments, detected when it was added (unnamed: counted)
    demo = page.locator(".ref-option", has_text="CMU 64_29")
    assert demo.locator(".segs").first.inner_text() == "3 segments"
    page.set_input_files("#video", str(clip))
    page.screenshot(path=str(shots / "upload.png"), full_page=True)
    page.get_by_role("button", name="Upload and analyse").click()
    live = []  # the live 3D view's answers: asked for once stage 2 is done, not every second
    page.on("response", lambda r: live.append(r.status) if r.url.endswith("/viewer/live") else 0)
    page.wait_for_url("**/analyses/*", timeout=30_000)
    page.wait_for_function("() => document.getElementById('stage-bar').value > 0", timeout=60_000)
    page.screenshot(path=str(shots / "progress.png"), full_page=True)
    assert page.locator("#stage-pct").inner_text().endswith("% overall")
    try:
        wait_results(page, timeout_ms=170_000)
    except PlaywrightTimeout as e:
        raise AssertionError(analysis_diagnosis(page, server)) from e
    assert page.locator("#progress-view").is_hidden()
    assert live.count(409) <= 1, live
    # stage names came over the stream, said in the performer's words
    stages = page.locator("#stage-list li").all_inner_texts()
    assert stages and all(len(s.split()) >= 2 for s in stages), stages
    assert page.locator("#plot svg polyline").count() >= 1
    ctx.close()


def test_results_overlay_plot_and_cursor_follow_the_video(
    server, browser, clip, clip_result, shots
):
    result = json.loads(json.dumps(clip_result))
    note = "The video matches the reported posture poorly in 3 of 12 frames."
    result["summary"]["messages"] = [*result["summary"]["messages"], note]
    for t, f in enumerate(result["frames"]):  # three frames the video does not confirm
        f["flags"] = [x for x in f["flags"] if x != "image_misfit"] + (
            ["image_misfit"] if t in (3, 4, 5) else []
        )
        f.pop("image_best", None)
        f.pop("image_best_joints_2d", None)
        if t == 4:  # what the video suggests there: the right ankle 25 px to the right
            f["image_best_joints_2d"] = [[u + 25.0 * (j == 6), v] for j, (u, v) in
                                         enumerate(f["joints_2d"])]  # fmt: skip
    aid = server.add_done_analysis("pat", clip, result)
    ctx = browser.new_context(viewport={"width": 1280, "height": 1000})
    page = ctx.new_page()
    sign_in(page, server.url, "pat@example.com", next_path=f"/analyses/{aid}")
    wait_results(page)
    # a coach's words only: no bone identifiers, flags or symbols of the data contract
    words = page.locator("main").inner_text()
    assert not re.search(r"->|image_misfit|eps=|t'=|_deg", words), words
    assert "Tempo: " in words
    go_to_frame(page, most_colourful_frame(clip_result))
    red, green = canvas_colours(page, "#overlay")
    page.locator("#stage-box").screenshot(path=str(shots / "overlay.png"))
    assert red > 10 and green > 10, (red, green)
    assert page.locator("#plot-svg polyline").count() >= 2
    # the axis fits the plotted curves, eps_t' and the two bones worst on average, with the
    # printable plot's heights
    labels = [t for t in page.locator("#plot-svg text").all_text_contents() if t.endswith("°")]
    bones = np.array([f["bone_errors_deg"] for f in result["frames"]])
    shown = bones[:, np.argsort(-bones.mean(0), kind="stable")[:2]]
    most = max(shown.max(), max(f["posture_error_deg"] for f in result["frames"]))
    assert max(int(t[:-1]) for t in labels) == media.plot_top(most), (labels, most)
    # frame 4's dashed amber skeleton (exact #fab005; the error colours all have blue 13)
    assert page.locator("#legend-image-best").is_visible()
    assert page.locator("#legend3d-image-best").count() == 1
    go_to_frame(page, 0)
    assert amber_pixels(page) == 0
    go_to_frame(page, 4)
    assert amber_pixels(page) > 50
    # the misfit frames are shaded on the plot, with a legend entry
    assert page.locator("#plot-svg .misfit-mark").count() == 3
    assert "video disagrees" in page.locator("#plot-svg").text_content()
    box = page.locator("#result-messages li")
    assert page.locator("#result-messages").is_visible()
    assert box.count() == len(result["summary"]["messages"])
    assert box.last.inner_text() == note
    assert page.locator(".seg-card").count() == len(clip_result["segments"])
    # degrees under 10 keep a decimal: a segment at 0.4 deg does not read "0 deg"
    for score in page.locator(".seg-card .score").all_inner_texts():
        assert re.fullmatch(r"\d\.\d°|\d{2,}°", score), score
    # the card of the segment holding the misfit frames says so, the others do not
    warned = page.locator(".seg-card .seg-misfit")
    assert warned.count() == len(
        {
            i
            for i, s in enumerate(result["segments"])
            if s["performer_start"] <= 5 and s["performer_end"] >= 3
        }
    )
    # its card opens at the first frame the video disagrees with
    page.locator(".seg-card", has=page.locator(".seg-misfit")).first.click()
    page.wait_for_function("() => document.getElementById('analysis').dataset.frame === '3'")
    counts = [int(t.split("disagrees in ")[1].split()[0]) for t in warned.all_inner_texts()]
    assert "mostly at right shin:" in " ".join(warned.all_inner_texts())
    assert sum(counts) >= 3, counts  # a boundary frame belongs to both of its segments
    page.wait_for_selector("#viewer3d:not([hidden]), #fallback3d:not([hidden])", timeout=30_000)
    page.wait_for_timeout(1500)  # let the 3D view draw
    page.screenshot(path=str(shots / "results.png"), full_page=True)
    # Playback moves the timeline cursor (and the frame the 3D view shows).
    go_to_frame(page, 0)
    x0 = float(page.get_attribute("#plot-cursor", "x1"))
    page.get_by_role("button", name="Play").click()
    page.wait_for_function(
        "() => +document.getElementById('analysis').dataset.frame >= 4", timeout=10_000
    )
    x1 = float(page.get_attribute("#plot-cursor", "x1"))
    assert x1 > x0
    t = page.evaluate("document.getElementById('video').currentTime")
    frame = int(page.evaluate("document.getElementById('analysis').dataset.frame"))
    assert abs(frame - t * clip_result["video"]["fps"]) <= 2
    # Clicking a segment card seeks there.
    page.evaluate("document.getElementById('video').pause()")
    last = clip_result["segments"][-1]
    page.locator(".seg-card").last.click()
    page.wait_for_function(
        f"() => document.getElementById('analysis').dataset.frame === '{last['performer_start']}'"
    )
    ctx.close()


def test_coach_review_comments_persist_and_exports_parse(server, browser, clip, clip_result, shots):
    aid = server.add_done_analysis("olive", clip, clip_result)
    ctx = browser.new_context(viewport={"width": 1280, "height": 1000}, accept_downloads=True)
    page = ctx.new_page()
    sign_in(page, server.url, COACH[0], COACH[1], next_path=f"/analyses/{aid}/review")
    wait_results(page)
    page.locator("#next").click()
    page.locator("#next").click()
    page.get_by_label("New comment").fill("Keep the left arm straight here")
    page.get_by_role("button", name="Add comment").click()
    page.wait_for_function("() => document.querySelectorAll('#comments li.comment').length === 1")
    page.get_by_label("New comment").fill("Too quick overall")
    page.get_by_label("Pin to").select_option(
        label=f"segment: {page.locator('.seg-card h3').first.inner_text()}"
    )
    page.get_by_role("button", name="Add comment").click()
    page.wait_for_function("() => document.querySelectorAll('#comments li.comment').length === 2")
    page.reload()
    wait_results(page)
    page.wait_for_function("() => document.querySelectorAll('#comments li.comment').length === 2")
    texts = page.locator("#comments li.comment").all_inner_texts()
    assert any("frame 2" in t and "left arm" in t for t in texts), texts
    assert page.locator("#segment-table tbody tr").count() == len(clip_result["segments"])
    cells = page.locator("#segment-table tbody tr").first.locator("td").all_inner_texts()
    assert len(cells) == 6 and (cells[-1] == "–" or " frames" in cells[-1]), cells
    page.screenshot(path=str(shots / "review.png"), full_page=True)

    with page.expect_download() as d:
        page.locator("#export-csv").click()
    rows = list(csv.reader(io.StringIO(open(d.value.path()).read())))
    assert len(rows) == 1 + len(clip_result["frames"])
    assert float(rows[1][4]) == pytest.approx(
        clip_result["frames"][0]["posture_error_deg"], abs=1e-3
    )
    with page.expect_download() as d:
        page.locator("#export-bvh").click()
    from engine.io.bvh import load_reference

    motion = load_reference(d.value.path()).motion
    assert motion.frames == len(clip_result["frames"])

    page.goto(f"{server.url}/analyses/{aid}/report")
    assert page.locator("svg.plot").count() == 1
    assert "Keep the left arm straight" in page.content()
    page.emulate_media(media="print")
    page.screenshot(path=str(shots / "report.png"), full_page=True)
    ctx.close()


def test_clicking_a_joint_reads_its_bend_for_the_performer_and_the_expert(
    server, browser, clip, clip_result, shots
):
    ctx, page, aid = open_done_analysis(server, browser, clip, clip_result)
    wait_results(page)
    page.wait_for_function("() => document.querySelectorAll('#angle-joint option').length > 13")
    knee = clip_result["frames"][0]["joints_2d"][2]  # the left knee, video pixels
    box = page.locator("#overlay").bounding_box()
    w, h = clip_result["video"]["width"], clip_result["video"]["height"]
    page.mouse.click(box["x"] + knee[0] * box["width"] / w, box["y"] + knee[1] * box["height"] / h)
    assert page.locator("#angle-joint option:checked").inner_text() == "Left knee"
    text = page.locator("#angle-readout").inner_text()
    angles = page.request.get(f"{server.url}/api/v1/analyses/{aid}/angles").json()

    def js_round(x: float) -> int:  # Math.round: halves up (Python's round goes to even)
        return int(np.floor(x + 0.5))

    you, expert = js_round(angles["performer"][0][1]), js_round(angles["expert"][0][1])
    assert text.startswith(f"you {you}°, the expert {expert}°"), text
    # it follows the frame
    go_to_frame(page, 3)
    assert page.locator("#angle-readout").inner_text().startswith(
        f"you {js_round(angles['performer'][3][1])}°"
    )
    # and how the body stands there: spine tilt, shoulder and hip turn, yours and the expert's
    you, them = angles["performer_posture"][3], angles["expert_posture"][3]
    stand = page.locator("#posture-readout").inner_text()
    assert stand.startswith(f"Spine {js_round(abs(you[0]))}° "), stand
    assert f"shoulders turned {js_round(abs(you[2]))}° (expert {js_round(abs(them[2]))}°)" in stand
    assert f"hips turned {js_round(abs(you[3]))}° (expert {js_round(abs(them[3]))}°)" in stand
    page.locator(".video-wrap").screenshot(path=str(shots / "joint-angle.png"))
    ctx.close()


def test_key_positions_step_through_the_motion(server, browser, clip, clip_result):
    ctx, page, _ = open_done_analysis(server, browser, clip, clip_result)
    wait_results(page)
    segs, first = clip_result["segments"], clip_result["frames"][0]["t"]
    keys = page.locator("#key-positions button")
    assert keys.count() == len(segs) + 1
    names = keys.all_inner_texts()
    assert all(n.startswith("Start of ") for n in names[:-1]) and names[-1].startswith("End of ")
    for k, frame in ((1, segs[1]["performer_start"]), (len(segs), segs[-1]["performer_end"])):
        keys.nth(k).click()
        page.wait_for_function(
            f"() => document.getElementById('analysis').dataset.frame === '{frame - first}'"
        )
    ctx.close()


def test_two_viewers_each_see_their_own_analysis(server, browser, clip, clip_result):
    other = dict(clip_result)
    other["frames"] = [dict(f, bone_errors_deg=[0.0] * 16, posture_error_deg=0.0)
                       for f in clip_result["frames"]]  # fmt: skip
    a = server.add_done_analysis("pat", clip, clip_result)
    b = server.add_done_analysis("olive", clip, other)
    pages = []
    for who, aid in (("pat", a), ("olive", b)):
        ctx = browser.new_context(viewport={"width": 1100, "height": 900})
        page = ctx.new_page()
        sign_in(page, server.url, f"{who}@example.com", next_path=f"/analyses/{aid}")
        pages.append((ctx, page, aid))
    for _, page, _ in pages:
        wait_results(page)
        go_to_frame(page, most_colourful_frame(clip_result))
    (_, pa, _), (_, pb, _) = pages
    assert "Pat Putter" in pa.locator("h1").inner_text()
    assert "Olive Iron" in pb.locator("h1").inner_text()
    red_a, _ = canvas_colours(pa, "#overlay")
    red_b, green_b = canvas_colours(pb, "#overlay")
    assert red_a > 10 and red_b == 0 and green_b > 10
    # Each 3D view is its own server (when viser is there; else both show the 2D fallback).
    for _, p, _ in pages:
        p.wait_for_selector("#viewer3d:not([hidden]), #fallback3d:not([hidden])", timeout=30_000)
    urls = [p.get_attribute("#viewer3d", "src") for _, p, _ in pages]
    if all(urls):
        assert urls[0] != urls[1]
    # Neither performer can open the other's analysis.
    assert pa.goto(f"{server.url}/analyses/{b}").status == 404
    for ctx, _, _ in pages:
        ctx.close()


def test_two_tabs_on_one_analysis_each_have_their_own_3d_view(server, browser, clip,
                                                               clip_result):  # fmt: skip
    """A coach and the performer look at one analysis: the coach seeking to the last frame
    moves the coach's 3D view only. Both views come through the app's own origin."""
    aid = server.add_done_analysis("pat", clip, clip_result)
    n = len(clip_result["frames"])
    tabs = []
    for email, password in (("pat@example.com", None), COACH):
        ctx = browser.new_context(viewport={"width": 1280, "height": 900})
        page = ctx.new_page()
        sign_in(page, server.url, email, *(() if password is None else (password,)),
                next_path=f"/analyses/{aid}")  # fmt: skip
        wait_results(page)
        page.wait_for_selector("#viewer3d:not([hidden]), #fallback3d:not([hidden])",
                               timeout=30_000)  # fmt: skip
        if page.locator("#viewer3d").is_hidden():
            pytest.skip(f"no 3D view here: {page.locator('#viewer-status').inner_text()}")
        tabs.append((ctx, page))
    (_, performer), (_, coach) = tabs
    srcs = [p.locator("#viewer3d").get_attribute("src") for p in (performer, coach)]
    assert all(s.startswith(f"/analyses/{aid}/3d/") for s in srcs) and srcs[0] != srcs[1]

    def view(page) -> np.ndarray:  # what the tab's 3D view shows now
        return _pixels_of(page.locator("#viewer3d").screenshot())

    def changed(a: np.ndarray, b: np.ndarray) -> int:
        return int((np.abs(a.astype(int) - b.astype(int)).max(-1) > 40).sum())

    for p in (performer, coach):
        p.frame_locator("#viewer3d").locator("canvas").first.wait_for(timeout=20_000)
        p.wait_for_timeout(2500)  # connected, drawn at the tab's frame
    before = {id(p): view(p) for p in (performer, coach)}
    go_to_frame(coach, n - 1)  # the swing's end: another posture
    deadline = time.monotonic() + 20
    while changed(before[id(coach)], view(coach)) < 300 and time.monotonic() < deadline:
        coach.wait_for_timeout(300)
    moved = changed(before[id(coach)], view(coach))
    performer.wait_for_timeout(1500)  # long enough for a shared view to have moved too
    still = changed(before[id(performer)], view(performer))
    assert moved >= 300 and still < 50, (moved, still)
    assert performer.evaluate("document.getElementById('analysis').dataset.frame") == "0"
    for ctx, _ in tabs:
        ctx.close()


def test_coach_dashboard_and_references(server, browser, clip, clip_result, shots, tmp_path):
    server.add_done_analysis("pat", clip, clip_result)
    ctx = browser.new_context(viewport={"width": 1280, "height": 900})
    page = ctx.new_page()
    sign_in(page, server.url, COACH[0], COACH[1])
    assert page.url.endswith("/dashboard")
    assert page.locator("#analyses-table tbody tr").count() >= 1
    page.get_by_label("Performer", exact=True).select_option(label="Olive Iron")
    page.get_by_label("Status").select_option("done")
    page.get_by_role("button", name="Filter").click()
    page.wait_for_url("**performer=*")
    for row in page.locator("#analyses-table tbody tr").all_inner_texts():
        assert "Pat Putter" not in row
    page.goto(f"{server.url}/dashboard")
    page.screenshot(path=str(shots / "dashboard.png"), full_page=True)

    page.goto(f"{server.url}/references")
    page.wait_for_selector(".ref-card")
    from tests.conftest import CMU

    page.locator("#ref-upload").get_by_label("Name", exact=True).fill("Second swing")
    page.get_by_label("BVH file").set_input_files(str(CMU / "64_29.bvh"))
    page.get_by_role("button", name="Upload reference").click()
    page.wait_for_function(
        "() => document.querySelectorAll('.ref-card').length === 2", timeout=30_000
    )
    card = page.locator(".ref-card", has_text="Second swing")
    # the detected segments of the upload (64_29: three) are counted for the coach
    card.get_by_label("Segment names (3 segments, one a line").fill("address\nbackswing\ndownswing")
    card.get_by_text("Per-bone weights and tolerances").click()
    card.get_by_label("left shin tolerance in degrees").fill("15")
    card.get_by_role("button", name="Save").click()
    card.get_by_text("Saved.").wait_for()
    page.wait_for_function("() => Array.from(document.images).every(i => i.complete)")
    page.screenshot(path=str(shots / "references.png"), full_page=True)
    page.reload()
    page.wait_for_selector(".ref-card")
    saved = page.locator(".ref-card", has_text="Second swing").get_by_label("Segment names")
    assert "backswing" in saved.input_value()
    # Delete, after a confirmation: the demo reference has analyses and stays, with the reason
    demo = page.locator(".ref-card", has_text="CMU 64_29 (golf swing)")
    page.once("dialog", lambda d: d.accept())
    demo.get_by_role("button", name="Delete reference").click()
    assert "delete them first" in demo.get_by_role("alert").inner_text()
    second = page.locator(".ref-card", has_text="Second swing")
    page.once("dialog", lambda d: d.dismiss())  # changing one's mind keeps it
    second.get_by_role("button", name="Delete reference").click()
    assert second.count() == 1
    kept = page.locator(".ref-card").count() - 1
    page.once("dialog", lambda d: d.accept())
    second.get_by_role("button", name="Delete reference").click()
    page.wait_for_function(f"() => document.querySelectorAll('.ref-card').length === {kept}")
    assert page.locator("#ref-done").inner_text() == "Deleted “Second swing”."
    ctx.close()


def test_phone_layout_upload_page(server, browser, shots):
    ctx = browser.new_context(
        viewport={"width": 390, "height": 844}, is_mobile=True, has_touch=True
    )
    page = ctx.new_page()
    sign_in(page, server.url, "pat@example.com", next_path="/upload")
    page.wait_for_selector(".ref-option canvas[data-ready=true]")
    assert page.locator("#video").get_attribute("accept") == "video/*"
    assert page.locator("#video").get_attribute("capture") is not None
    width = page.evaluate("document.documentElement.scrollWidth")
    assert width <= 390, f"horizontal scroll on a phone: {width}px"
    page.screenshot(path=str(shots / "upload-phone.png"), full_page=True)
    ctx.close()


def test_one_repetition_of_several_is_shown_where_it_is_in_the_video(server, browser, clip,
                                                                     clip_result, shots):
    """A result that covers file frames 4..11 of the clip (the first of two repetitions):
    the page lists the repetitions, numbers frames as the file does, and draws no skeleton
    where nothing was analysed."""
    result = json.loads(json.dumps(clip_result))
    result["frames"] = result["frames"][4:]
    result["video"]["first_frame"] = 4
    for seg in result["segments"]:
        seg["performer_start"] = max(seg["performer_start"], 4)
        seg["performer_end"] = max(seg["performer_end"], seg["performer_start"])
    fps = result["video"]["fps"]
    result["summary"]["repetitions"] = [
        {"start": 4, "end": 12, "start_s": round(4 / fps, 2), "end_s": round(12 / fps, 2),
         "analysed": True},
        {"start": 12, "end": 20, "start_s": round(12 / fps, 2), "end_s": round(20 / fps, 2),
         "analysed": False},
    ]  # fmt: skip
    aid = server.add_done_analysis("pat", clip, result)
    page = browser.new_context(viewport={"width": 1280, "height": 1000}).new_page()
    sign_in(page, server.url, "pat@example.com", next_path=f"/analyses/{aid}")
    wait_results(page)
    reps = page.locator("#repetition-list li")
    assert page.locator("#repetitions").is_visible() and reps.count() == 2
    assert reps.first.inner_text().endswith("(analysed)")
    assert "(analysed)" not in reps.last.inner_text()
    go_to_frame(page, 0)  # the first analysed frame is the file's frame 4
    assert page.locator("#frame-label").inner_text().startswith("frame 4 / 11")
    assert sum(canvas_colours(page, "#overlay")) > 0
    # before the analysed part: the video plays on, without a skeleton
    page.evaluate("() => { const v = document.getElementById('video'); v.currentTime = 1.5 / "
                  f"{fps}; }}")  # fmt: skip
    page.wait_for_function("() => document.getElementById('frame-label').textContent"
                           ".includes('not analysed')")  # fmt: skip
    assert page.locator("#frame-label").inner_text().startswith("frame 1 /")
    assert canvas_colours(page, "#overlay") == (0, 0)
    page.screenshot(path=str(shots / "repetitions.png"), full_page=True)
    # the other repetition is analysed on its own: a new analysis of its frames, its page
    assert reps.first.locator("button", has_text="Analyse this one").count() == 0
    reps.last.locator("button", has_text="Analyse this one").click()
    page.wait_for_url(lambda url: "/analyses/" in url and aid not in url)
    new_id = page.url.rsplit("/", 1)[-1]
    record = page.evaluate("async (u) => (await fetch(u)).json()", f"/api/v1/analyses/{new_id}")
    assert (record["frames_start"], record["frames_end"]) == (12, 20)
    page.evaluate("async (u) => fetch(u, {method: 'DELETE'})", f"/api/v1/analyses/{new_id}")


def test_a_coach_sets_segment_boundaries_on_the_plot(server, browser, shots):
    """Drag a boundary on the expert's hand-speed plot, nudge it with the keys, add one,
    save: the reference's segments are the ones shown; then back to the detected ones."""
    from tests.conftest import CMU

    ctx = browser.new_context(viewport={"width": 1280, "height": 900})
    page = ctx.new_page()
    sign_in(page, server.url, COACH[0], COACH[1])
    page.goto(f"{server.url}/references")
    page.wait_for_selector(".ref-card")
    page.locator("#ref-upload").get_by_label("Name", exact=True).fill("Boundaries swing")
    page.get_by_label("BVH file").set_input_files(str(CMU / "64_29.bvh"))
    page.get_by_role("button", name="Upload reference").click()
    card = page.locator(".ref-card", has_text="Boundaries swing")
    card.locator(".boundary-plot polyline").wait_for(timeout=30_000)
    rid = card.get_attribute("aria-labelledby").removeprefix("ref").removesuffix("-h")
    url = f"{server.url}/api/v1/references/{rid}"
    before = page.request.get(url).json()["derived"]["segments"]
    assert len(before) == 4  # 64_29: three detected segments, then the last frame
    line = card.locator('.boundary[data-index="1"] line')
    line.scroll_into_view_if_needed()
    box = line.bounding_box()
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.mouse.down()
    page.mouse.move(box["x"] + 40, box["y"] + box["height"] / 2, steps=5)
    page.mouse.up()
    page.keyboard.press("ArrowRight")
    page.keyboard.press("ArrowRight")
    card.get_by_label("Key positions").fill("address\ntop\nimpact\nfinish")
    card.get_by_role("button", name="Add a boundary").click()
    shown = card.locator(".boundary-text").inner_text()
    starts = [int(v) for v in shown.split("frames ")[1].split(" (")[0].split(", ")]
    # the dragged boundary moved right, and the new one splits the longest segment before it
    assert len(starts) == 4 and starts[2] > before[1] + 2, (shown, before)
    assert starts[1] == int((before[0] + starts[2]) / 2 + 0.5) and starts[3] == before[2]
    assert card.get_by_label("Segment names").input_value().count("\n") == 3  # four, one new
    card.get_by_role("button", name="Save").click()
    card.get_by_text("Saved.").wait_for()
    ref = page.request.get(url).json()
    assert ref["derived"]["segments"] == [*starts, before[-1]]
    assert len(ref["segment_names"]) == 4
    # the key positions followed: a new one where the boundary was added
    assert ref["domain"]["key_position_names"] == ["address", "key position 2", "top", "impact",
                                                   "finish"]  # fmt: skip
    page.locator(".ref-card", has_text="Boundaries swing").screenshot(
        path=str(shots / "reference-boundaries.png")
    )
    card = page.locator(".ref-card", has_text="Boundaries swing")
    card.get_by_role("button", name="Use the detected boundaries").click()
    card.get_by_role("button", name="Save").click()
    card.get_by_text("Saved.").wait_for()
    assert page.request.get(url).json()["derived"]["segments"] == before
    page.request.delete(url)
    ctx.close()


def _ink_pixels(page) -> int:
    """Pixels of the drawing ink (#f03e3e) on the video's overlay."""
    return page.evaluate("""() => {
        const c = document.getElementById('overlay'), d = c.getContext('2d')
            .getImageData(0, 0, c.width, c.height).data;
        let n = 0;
        for (let i = 0; i < d.length; i += 4)
            if (d[i] > 200 && d[i + 1] < 90 && d[i + 2] < 90 && d[i + 3] > 200) n++;
        return n;
    }""")


def test_a_coach_draws_over_a_frame_and_the_drawing_comes_back(
    server, browser, clip, clip_result, shots
):
    aid = server.add_done_analysis("olive", clip, clip_result)
    ctx = browser.new_context(viewport={"width": 1280, "height": 1000})
    page = ctx.new_page()
    sign_in(page, server.url, COACH[0], COACH[1], next_path=f"/analyses/{aid}")
    wait_results(page)
    page.get_by_role("checkbox", name="Skeleton").uncheck()  # only the drawing on the overlay
    go_to_frame(page, 3)
    assert _ink_pixels(page) == 0
    page.get_by_role("button", name="Draw on the video").click()
    page.locator("#overlay").scroll_into_view_if_needed()
    box = page.locator("#overlay").bounding_box()
    page.mouse.move(box["x"] + 0.2 * box["width"], box["y"] + 0.3 * box["height"])
    page.mouse.down()
    for k in range(1, 11):
        page.mouse.move(box["x"] + (0.2 + 0.04 * k) * box["width"],
                        box["y"] + (0.3 + 0.03 * k) * box["height"])  # fmt: skip
    page.mouse.up()
    assert _ink_pixels(page) > 50
    page.get_by_label("New comment").fill("Elbow along this line")
    page.get_by_role("button", name="Add comment").click()
    page.wait_for_function("() => document.querySelectorAll('#comments li.comment').length === 1")
    (c,) = page.request.get(f"{server.url}/api/v1/analyses/{aid}/comments").json()["items"]
    assert c["frame"] == clip_result["frames"][3]["t"] and len(c["drawing"]) == 1
    (x0, y0), (x1, y1) = c["drawing"][0][0], c["drawing"][0][-1]
    assert (x0, y0) == pytest.approx((0.2, 0.3), abs=0.02)
    assert (x1, y1) == pytest.approx((0.6, 0.6), abs=0.02)
    page.reload()
    wait_results(page)
    page.get_by_role("checkbox", name="Skeleton").uncheck()
    page.wait_for_function("() => document.querySelectorAll('#comments li.comment').length === 1")
    assert "✎ drawing" in page.locator("#comments li.comment").inner_text()
    assert _ink_pixels(page) == 0  # frame 0: not the drawing's frame
    page.locator("#comments .pin").click()  # the comment's pin goes to its frame
    page.wait_for_function("() => document.getElementById('analysis').dataset.frame === '3'")
    assert _ink_pixels(page) > 50
    page.locator(".video-wrap").screenshot(path=str(shots / "drawing.png"))
    ctx.close()
