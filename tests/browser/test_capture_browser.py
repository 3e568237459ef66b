"""The 3D capture pages in real Chromium against `coach serve` (embedded worker, real
engine): a performer uploads a clip, the capture runs, its motion downloads as BVH; a coach
puts it in the reference library."""

from __future__ import annotations

from tests.browser.conftest import COACH, sign_in


def test_a_capture_from_upload_to_reference(server, browser, clip, shots):
    page = browser.new_context(viewport={"width": 1280, "height": 1000}).new_page()
    sign_in(page, server.url, "olive@example.com", next_path="/captures")
    assert page.locator("nav a[aria-current=page]").inner_text() == "3D capture"
    page.locator("#capture-button").click()  # no video yet: said, nothing sent
    assert page.locator("#capture-form-error").inner_text() == "Choose a video first."
    page.set_input_files("#capture-file", str(clip))
    page.fill("#height", "1.8")
    page.locator("#capture-button").click()
    page.wait_for_url("**/captures/*")
    page.wait_for_selector("#capture-done:not([hidden])", timeout=120_000)
    assert page.locator("#capture-status").count() == 1
    bvh = page.evaluate("async () => (await fetch(document.getElementById('dl-bvh').href)).text()")
    assert bvh.startswith("HIERARCHY") and "ROOT Hips" in bvh
    assert "Frames: 12" in bvh
    page.screenshot(path=str(shots / "capture.png"), full_page=True)
    capture_url = page.url
    # a performer cannot add references; a coach can, from the same page
    assert page.locator("#to-reference").count() == 0
    coach = browser.new_context().new_page()
    sign_in(coach, server.url, COACH[0], COACH[1], next_path=capture_url.split(server.url)[1])
    coach.wait_for_selector("#capture-done:not([hidden])", timeout=30_000)
    coach.fill("#reference-name", "Olive's swing")
    coach.locator("#to-reference button").click()
    coach.wait_for_selector("#reference-done:not([hidden])")
    refs = coach.evaluate("async () => (await fetch('/api/v1/references?limit=50')).json()")
    made = [r["id"] for r in refs["items"] if r["name"] == "Olive's swing"]
    assert made
    # leave the shared server's library as the other browser tests expect it
    coach.evaluate("async (u) => fetch(u, {method: 'DELETE'})", f"/api/v1/references/{made[0]}")
    listed = page.evaluate("async () => (await fetch('/api/v1/captures')).json()")
    assert listed["total"] >= 1
