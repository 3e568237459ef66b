"""Issue 7's finishing items in real Chromium: the framed 3D view, the looping reference
preview, invite links, the printable report's stills and upload errors next to the input."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.browser.conftest import COACH, open_done_analysis, sign_in

pytestmark = pytest.mark.browser


def _pixels(png: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), np.int32)


def _skeleton_box(rgb: np.ndarray) -> tuple[int, float, float]:
    """Coloured (saturated) pixels: the bones. Grid, labels and panel are grey or white.

    Returns (count, box height / image height, box width / image width).
    """
    sat = rgb.max(-1) - rgb.min(-1)
    ys, xs = np.nonzero(sat > 70)
    if not len(ys):
        return 0, 0.0, 0.0
    h, w = rgb.shape[:2]
    # Robust box: ignore the 0.5 % most outlying pixels (e.g. a notification's accent bar).
    y0, y1 = np.percentile(ys, [0.5, 99.5])
    x0, x1 = np.percentile(xs, [0.5, 99.5])
    return int(len(ys)), (y1 - y0) / h, (x1 - x0) / w


def test_3d_view_frames_the_body_with_the_panel_collapsed(
    server, browser, clip, clip_result, shots
):
    ctx, page, _ = open_done_analysis(server, browser, clip, clip_result, height=900)
    page.wait_for_selector("#viewer3d:not([hidden]), #fallback3d:not([hidden])", timeout=30_000)
    if page.locator("#viewer3d").is_hidden():
        pytest.skip(f"no 3D view here: {page.locator('#viewer-status').inner_text()}")
    frame = page.frame_locator("#viewer3d")
    frame.locator("canvas").first.wait_for(timeout=20_000)
    close = frame.get_by_role("button", name="Close")  # headless Chromium's software-GL notice
    page.wait_for_timeout(1500)
    for i in range(close.count()):
        close.nth(i).click()
    page.wait_for_timeout(800)
    box = page.locator("#viewer3d").bounding_box()
    assert box["width"] >= 576, "narrower than this, viser switches to its phone layout"
    png = page.locator("#viewer3d").screenshot(path=str(shots / "viewer3d-framed.png"))
    page.locator(".three-wrap").screenshot(path=str(shots / "viewer3d-with-legend.png"))
    count, height, width = _skeleton_box(_pixels(png))
    # Viser's default camera (3 m out on every axis) left the figure ~15 % of the frame high.
    assert count > 2000 and height > 0.4, (count, height, width)
    # The control panel starts minimised: its frame slider is not shown over the scene.
    assert (
        frame.get_by_text("other possible postures").count() == 0
        or not frame.get_by_text("other possible postures").first.is_visible()
    )
    assert page.locator("#legend3d").is_visible()
    ctx.close()


def test_reference_picker_preview_loops(server, browser, shots):
    ctx = browser.new_context(viewport={"width": 1280, "height": 900})
    page = ctx.new_page()
    sign_in(page, server.url, "olive@example.com", next_path="/upload")
    canvas = page.locator(".ref-option canvas[data-ready=true]").first
    canvas.wait_for()
    a = canvas.screenshot()
    f0 = int(canvas.get_attribute("data-frame"))
    page.wait_for_timeout(700)
    b = canvas.screenshot(path=str(shots / "reference-preview.png"))
    f1 = int(canvas.get_attribute("data-frame"))
    assert f1 != f0
    assert np.abs(_pixels(a) - _pixels(b)).sum() > 0, "the preview did not move"
    ink = (_pixels(b)[..., 2] > 150) & (_pixels(b)[..., 0] < 120)  # the blue skeleton
    assert ink.sum() > 200
    page.screenshot(path=str(shots / "upload-preview.png"))
    ctx.close()


def test_invite_link_signs_a_new_performer_in_once(server, browser, shots):
    coach_ctx = browser.new_context(viewport={"width": 1280, "height": 900})
    page = coach_ctx.new_page()
    sign_in(page, server.url, COACH[0], COACH[1])
    page.get_by_label("Their name (they can change it)").fill("Nina New")
    page.get_by_role("button", name="Create invite link").click()
    link = page.locator("#invite-link")
    link.wait_for()
    url = link.input_value()
    assert "/join/" in url
    page.screenshot(path=str(shots / "invite-created.png"))
    coach_ctx.close()

    ctx = browser.new_context(viewport={"width": 800, "height": 800})
    page = ctx.new_page()
    page.goto(url)
    assert page.get_by_label("Your name").input_value() == "Nina New"
    page.get_by_label("Email").fill("nina@example.com")
    page.get_by_label("Password").fill("nina-password-1")
    page.screenshot(path=str(shots / "join.png"))
    page.get_by_role("button", name="Join and sign in").click()
    page.wait_for_url("**/upload")
    assert "Nina New (performer)" in page.locator(".who").inner_text()
    ctx.close()

    again = browser.new_context().new_page()
    r = again.goto(url)
    assert r.status == 410 and "already been used" in again.content()
    sign_in(again, server.url, "nina@example.com", "nina-password-1")
    assert again.url.endswith("/analyses")  # a performer's home: their attempts
    again.context.close()


def test_printable_report_has_stills_and_segment_table(server, browser, clip, clip_result, shots):
    aid = server.add_done_analysis("olive", clip, clip_result)
    ctx = browser.new_context(viewport={"width": 1000, "height": 1200})
    page = ctx.new_page()
    sign_in(page, server.url, "olive@example.com", next_path=f"/analyses/{aid}/report")
    stills = page.locator(".still img")
    assert 1 <= stills.count() <= 4
    page.wait_for_function(
        "() => Array.from(document.images).every(i => i.complete && i.naturalWidth)"
    )
    rgb = _pixels(stills.first.screenshot())
    warm = (rgb[..., 0] > 180) | (rgb[..., 1] > 180)
    red_or_green = warm & (rgb[..., 2] < 80)
    assert red_or_green.sum() > 30, "no skeleton drawn on the still"
    rows = page.locator("table.list tbody tr")
    assert rows.count() == len(clip_result["segments"])
    page.emulate_media(media="print")
    assert page.locator(".no-print").is_hidden()
    page.screenshot(path=str(shots / "report-print.png"), full_page=True)
    pdf = page.pdf(format="A4", print_background=True)
    assert pdf[:4] == b"%PDF" and pdf.count(b"/Type /Page") - pdf.count(b"/Type /Pages") <= 2
    ctx.close()


def test_upload_errors_are_shown_next_to_the_file_input(server, browser, shots, tmp_path):
    ctx = browser.new_context(viewport={"width": 1000, "height": 900})
    page = ctx.new_page()
    sign_in(page, server.url, "pat@example.com", next_path="/upload")
    page.wait_for_selector(".ref-option input")
    # Not a video by type: refused before upload.
    text = tmp_path / "notes.txt"
    text.write_text("not a video")
    page.set_input_files("#video", str(text))
    err = page.locator("#video-error")
    err.wait_for()
    assert "not a video" in err.inner_text()
    assert page.evaluate("document.activeElement.id") == "video"
    # Named like a video but not one: the API's message, next to the input, focus there.
    fake = tmp_path / "swing.mp4"
    fake.write_bytes(b"\x00\x00\x00\x18ftypmp42" + b"garbage" * 500)
    page.set_input_files("#video", str(fake))
    assert err.is_hidden()
    page.locator("#upload-button").focus()
    page.get_by_role("button", name="Upload and analyse").click()
    page.wait_for_function("() => !document.getElementById('video-error').hidden", timeout=20_000)
    assert "cannot be analysed as a video" in err.inner_text()
    assert page.evaluate("document.activeElement.id") == "video"
    assert page.locator("#video").get_attribute("aria-invalid") == "true"
    page.locator("fieldset").last.screenshot(path=str(shots / "upload-error.png"))
    ctx.close()


def test_the_upload_page_checks_the_first_frame_before_uploading(server, browser, clip, shots,
                                                                  tmp_path):  # fmt: skip
    """The filming guide is on the page; choosing a video checks its first frame at once: the
    test clip (whole body) passes, a real squat clip with the legs cut off is told why."""
    from engine.io.encode import write_video
    from engine.io.video import read_video
    from tests.engine.stages.test_framing import SQUAT

    v = read_video(SQUAT, height=0, max_frames=6)
    cut = tmp_path / "cut.mp4"
    write_video(cut, np.ascontiguousarray(v.frames[:, : int(0.6 * v.frames.shape[1]) // 2 * 2]),
                v.fps)  # fmt: skip
    ctx = browser.new_context(viewport={"width": 1000, "height": 1100})
    page = ctx.new_page()
    sign_in(page, server.url, "pat@example.com", next_path="/upload")
    guide = page.locator(".filming-guide")
    assert "Start in the expert's first posture" in guide.inner_text()
    page.wait_for_function("() => document.querySelector('.filming-guide img').naturalWidth > 0")
    check = page.locator("#framing-check")
    page.set_input_files("#video", str(clip))
    page.wait_for_selector("#framing-check[data-state=ok], #framing-check[data-state=problems]")
    assert check.get_attribute("data-state") == "ok", check.inner_text()
    page.set_input_files("#video", str(cut))
    page.wait_for_selector("#framing-check[data-state=problems]", timeout=20_000)
    assert "out of the picture" in check.inner_text()
    assert page.get_by_role("button", name="Upload and analyse").is_enabled()  # a warning only
    page.locator("main").screenshot(path=str(shots / "upload-framing-check.png"))
    # A video this browser cannot decode is left to the engine's own first-frame check.
    opaque = tmp_path / "opaque.mp4"
    opaque.write_bytes(b"\x00\x00\x00\x18ftypmp42" + bytes(range(256)) * 64)
    page.set_input_files("#video", str(opaque))
    page.wait_for_selector("#framing-check[data-state=undecodable]", timeout=20_000)
    assert "checked once it is uploaded" in check.inner_text()
    ctx.close()


def test_at_phone_width_the_3d_view_keeps_its_panel_minimised(
    server, browser, clip, clip_result, shots
):
    """Viser's phone layout opens its controls over the scene; the page keeps the frame at
    580 CSS px, scaled to the screen, so the scene shows the bodies, not the panel."""
    ctx, page, _ = open_done_analysis(server, browser, clip, clip_result, width=390, height=844)
    page.wait_for_selector("#viewer3d:not([hidden]), #fallback3d:not([hidden])", timeout=30_000)
    if page.locator("#viewer3d").is_hidden():
        pytest.skip(f"no 3D view here: {page.locator('#viewer-status').inner_text()}")
    iframe = page.locator("#viewer3d")
    assert 0.4 < float(iframe.get_attribute("data-scale")) < 1
    box = iframe.bounding_box()
    assert box["width"] <= 390, "the scaled frame fits the screen"
    frame = page.frame_locator("#viewer3d")
    frame.locator("canvas").first.wait_for(timeout=20_000)
    page.wait_for_timeout(1500)
    close = frame.get_by_role("button", name="Close")  # headless Chromium's software-GL notice
    for i in range(close.count()):
        close.nth(i).click()
    page.wait_for_timeout(800)
    iframe.scroll_into_view_if_needed()
    png = iframe.screenshot(path=str(shots / "viewer3d-phone.png"))
    count, height, _ = _skeleton_box(_pixels(png))
    assert count > 500 and height > 0.4, (count, height)
    settings = frame.get_by_text("Orbit Origin Tool")  # the phone sheet's settings, if open
    assert settings.count() == 0 or not settings.first.is_visible()
    ctx.close()


def _hevc(path: Path, frames: np.ndarray, fps: float) -> Path:
    """An HEVC (H.265) MP4: what an iPhone records, which many browsers cannot decode."""
    import av

    with av.open(str(path), "w") as out:
        stream = out.add_stream("libx265", rate=int(round(fps)))
        stream.width, stream.height, stream.pix_fmt = frames.shape[2], frames.shape[1], "yuv420p"
        stream.options = {"x265-params": "log-level=error"}
        for f in frames:
            out.mux(stream.encode(av.VideoFrame.from_ndarray(f, format="rgb24")))
        out.mux(stream.encode(None))
    return path


def test_the_analysis_says_what_the_first_frame_shows_while_it_runs(
    server, browser, shots, tmp_path
):
    """An HEVC upload through the API, the legs cut off: no browser checked its first frame,
    so the analysis page says what to change as soon as stages 0-2 are done."""
    from engine.io.video import read_video
    from tests.engine.stages.test_framing import SQUAT

    v = read_video(SQUAT, height=240, max_frames=12)
    cut = np.ascontiguousarray(v.frames[:, : int(0.6 * v.frames.shape[1]) // 2 * 2])
    video = _hevc(tmp_path / "cut-hevc.mp4", cut, v.fps)
    ctx = browser.new_context(viewport={"width": 1000, "height": 1000})
    page = ctx.new_page()
    sign_in(page, server.url, "pat@example.com")
    r = page.request.post(f"{server.url}/api/v1/analyses", multipart={
        "video": {"name": "cut.mp4", "mimeType": "video/mp4", "buffer": video.read_bytes()},
        "reference_id": str(server.reference_id)})  # fmt: skip
    assert r.status == 201, r.text()
    aid = r.json()["id"]
    page.goto(f"{server.url}/analyses/{aid}")
    try:
        # while it runs; should it end first, the result's messages say the same
        shown = page.wait_for_selector(
            "#framing-warnings:not([hidden]) li, #result-messages:not([hidden]) li",
            timeout=120_000,
        )
        running = shown.evaluate("e => !!e.closest('#framing-warnings')")
        box = page.locator("#framing-warnings" if running else "#result-messages")
        page.wait_for_function(
            "() => /feet are out of the picture/.test(document.body.innerText)", timeout=60_000
        )
        assert "feet are out of the picture" in box.inner_text()
        page.locator("#progress-view" if running else "#results").screenshot(
            path=str(shots / "first-frame-warning.png")
        )
    finally:
        page.request.post(f"{server.url}/api/v1/analyses/{aid}/cancel")
    ctx.close()
