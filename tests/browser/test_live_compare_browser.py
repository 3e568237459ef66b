"""Issue 7's results experience, the last two pieces, in real Chromium: the 3D view filling in
while the real embedded worker runs, and two attempts of one performer side by side."""

from __future__ import annotations

import io
import json
import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.browser.conftest import COACH, SOURCE_VIDEO, sign_in

pytestmark = pytest.mark.browser


def _pixels(png: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), np.int32)


def _bone_pixels(rgb: np.ndarray) -> dict[str, int]:
    """Counts of the scene's bone colours: the expert's blue-grey, error red/yellow/green.

    Only the middle of the view, below its top: viser's notices (an orange bar, a green
    "Connected" icon) sit in the corners.
    """
    h, w = rgb.shape[:2]
    rgb = rgb[int(0.12 * h) :, int(0.3 * w) : int(0.7 * w)]
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return {
        "reference": int(((b > 160) & (b - r > 50) & (b - g > 30)).sum()),
        "coloured": int(((np.maximum(r, g) - b > 70) & (np.abs(r - g) > 40)).sum()),
    }


@pytest.fixture(scope="session")
def long_clip(tmp_path_factory) -> Path:
    """36 frames (every 2nd of the first 72, 15 fps): stage 3 takes several seconds, so the
    partial scene is on screen long enough to be seen."""
    from engine.io.encode import write_video
    from engine.io.video import read_video

    v = read_video(SOURCE_VIDEO, height=0, max_frames=72)
    path = tmp_path_factory.mktemp("long-clip") / "swing36.mp4"
    write_video(path, v.frames[::2], v.fps / 2)
    return path


def _close_notices(frame, page) -> None:
    close = frame.get_by_role("button", name="Close")  # headless Chromium's software-GL notice
    for i in range(close.count()):
        try:
            close.nth(i).click(timeout=1000)
        except Exception:
            pass


def _upload_clip(browser, server, clip: Path):
    """Olive signed in, her upload of ``clip`` queued: ``(context, page, analysis id)``."""
    ctx = browser.new_context(viewport={"width": 1280, "height": 1100})
    page = ctx.new_page()
    sign_in(page, server.url, "olive@example.com")
    r = page.request.post(
        f"{server.url}/api/v1/analyses",
        multipart={
            "video": {"name": "swing.mp4", "mimeType": "video/mp4",
                      "buffer": clip.read_bytes()},
            "reference_id": str(server.reference_id),
        },
    )  # fmt: skip
    assert r.status == 201, r.text()
    return ctx, page, r.json()["id"]


def test_3d_view_fills_in_while_the_analysis_runs(server, browser, long_clip, shots):
    ctx, page, aid = _upload_clip(browser, server, long_clip)
    page.goto(f"{server.url}/analyses/{aid}")
    live = page.locator("#live3d")
    page.wait_for_selector(
        "#live3d[data-phase=reference], #live3d[data-phase=candidates]", timeout=90_000
    )
    frame = page.frame_locator("#live-viewer3d")
    frame.locator("canvas").first.wait_for(timeout=20_000)
    page.wait_for_timeout(1200)
    _close_notices(frame, page)
    page.wait_for_timeout(600)
    png = page.locator("#live-viewer3d").screenshot()
    phase = live.get_attribute("data-phase")
    status = page.locator("#analysis").get_attribute("data-status")
    page.locator("#progress-view").screenshot(path=str(shots / "live-3d.png"))
    assert phase in ("reference", "candidates") and status != "done", (phase, status)
    px = _bone_pixels(_pixels(png))
    assert px["reference"] > 300, px  # the aligned expert is drawn
    assert px["coloured"] < 50, px  # no error colours yet
    assert "3D:" in page.locator("#live3d-status").inner_text()
    # Candidates arrive as stage-3 chunks finish (unless the whole stage slipped between polls).
    page.wait_for_function(
        "() => ['candidates', 'done'].includes(document.getElementById('live3d').dataset.phase)"
        " || document.getElementById('analysis').dataset.status === 'done'",
        timeout=90_000,
    )
    # Then the finished, coloured scene.
    page.wait_for_selector("#analysis[data-ready=true]", timeout=120_000)
    assert live.is_hidden()
    page.wait_for_selector("#viewer3d:not([hidden])", timeout=30_000)
    done = page.frame_locator("#viewer3d")
    done.locator("canvas").first.wait_for(timeout=20_000)
    page.wait_for_timeout(1500)
    _close_notices(done, page)
    page.wait_for_timeout(600)
    px = _bone_pixels(_pixels(page.locator("#viewer3d").screenshot()))
    page.locator(".three-wrap").screenshot(path=str(shots / "live-3d-done.png"))
    assert px["coloured"] > 300, px
    ctx.close()


def _improved(result: dict) -> dict:
    """The same attempt with every error 30 % smaller (a later, better attempt)."""
    import copy

    r = copy.deepcopy(result)
    for f in r["frames"]:
        f["posture_error_deg"] *= 0.7
        f["bone_errors_deg"] = [e * 0.7 for e in f["bone_errors_deg"]]
    for s in r["segments"]:
        s["mean_error_deg"] *= 0.7
    return r


def test_two_attempts_side_by_side(server, browser, clip, clip_result, shots):
    before = server.add_done_analysis("pat", clip, clip_result)
    after = server.add_done_analysis("pat", clip, _improved(clip_result))
    pid = server.performers["pat"]
    ctx = browser.new_context(viewport={"width": 1280, "height": 1000})
    page = ctx.new_page()
    sign_in(page, server.url, COACH[0], COACH[1])
    # The entry point: the dashboard links to the performer's progress.
    page.goto(f"{server.url}/dashboard?performer={pid}")
    page.locator("a.progress-link").first.click()
    page.wait_for_url(f"**/performers/{pid}/compare")
    page.wait_for_selector(".history-table tbody tr")
    assert page.locator(".trend circle").count() >= 2
    # By default the two latest attempts of the same reference: A before, B after.
    page.wait_for_selector("#compare[data-ready=true]")
    assert page.locator(f"tr[data-id='{before}'] input[name=pick-a]").is_checked()
    assert page.locator(f"tr[data-id='{after}'] input[name=pick-b]").is_checked()
    assert "better" in page.locator("#cmp-summary").inner_text()
    rows = page.locator("#cmp-table tbody tr")
    assert rows.count() == len(clip_result["segments"])
    assert page.locator("#cmp-table tbody tr[data-change=better]").count() >= 1
    assert page.locator("#cmp-plot-svg polyline.curve-a").count() == 1
    assert page.locator("#cmp-plot-svg polyline.curve-b").count() == 1
    page.wait_for_function(
        "() => ['video-a', 'video-b'].every(i => document.getElementById(i).readyState >= 2)",
        timeout=30_000,
    )
    page.screenshot(path=str(shots / "compare.png"), full_page=True)
    # Swapped by hand: worse, and the address says which two.
    page.locator(f"tr[data-id='{after}'] input[name=pick-a]").check()
    page.locator(f"tr[data-id='{before}'] input[name=pick-b]").check()
    page.wait_for_function(
        "() => document.getElementById('cmp-summary').textContent.includes('worse')"
    )
    assert f"a={after}" in page.url and f"b={before}" in page.url
    ctx.close()


@pytest.fixture(scope="session")
def whole_clip(tmp_path_factory) -> Path:
    """The whole swing, every 4th frame (35 frames): its first segment ends near the middle,
    so the chunks that complete it finish while the second half still waits."""
    from engine.io.encode import write_video
    from engine.io.video import read_video

    v = read_video(SOURCE_VIDEO, height=0)
    path = tmp_path_factory.mktemp("whole-clip") / "swing35.mp4"
    write_video(path, v.frames[::4], v.fps / 4)
    return path


def _frozen_worker(work_dir: Path, timeout_s: float = 120.0) -> int:
    """Wait for the worker to write the provisional result, then stop its process group
    (SIGSTOP: a worker that is slow to finish the rest); returns the group to continue."""
    deadline = time.monotonic() + timeout_s
    while not (work_dir / "provisional.json").exists():
        assert time.monotonic() < deadline, "no provisional result was written"
        assert not (work_dir / "result.json").exists(), "the final result came first"
        time.sleep(0.02)
    owner = json.loads((work_dir / "heartbeat").read_text())
    group = os.getpgid(int(owner["pid"]))
    os.killpg(group, signal.SIGSTOP)
    return group


def test_the_first_segments_show_before_the_analysis_ends(server, browser, whole_clip, shots):
    ctx, page, aid = _upload_clip(browser, server, whole_clip)
    from app import crud

    with server.sessions()() as s:
        work_dir = Path(crud.get_analysis(s, club_id=server.club_id, analysis_id=aid).work_dir)
    page.goto(f"{server.url}/analyses/{aid}")
    group = _frozen_worker(work_dir)
    try:
        assert not (work_dir / "result.json").exists()
        page.wait_for_selector("#first-results:not([hidden]) .seg-card", timeout=20_000)
        note = page.locator("#first-results-note").inner_text()
        assert "Provisional" in note and "3 segments" in note, note
        assert "analysed (frames 0–" in note, note
        cards = page.locator("#first-cards .seg-card")
        assert 1 <= cards.count() < 3
        assert "°" in cards.first.inner_text() and "Tempo" in cards.first.inner_text()
        page.locator("#progress-view").screenshot(path=str(shots / "first-results.png"))
    finally:
        os.killpg(group, signal.SIGCONT)
    page.wait_for_selector("#analysis[data-ready=true]", timeout=120_000)
    assert page.locator("#progress-view").is_hidden()
    assert page.locator("#segment-cards .seg-card").count() > cards.count()
    ctx.close()
