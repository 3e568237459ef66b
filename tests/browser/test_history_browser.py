"""My analyses and the coach's to-review list in Chromium (issue 21, item 1)."""

from __future__ import annotations

import pytest

from tests.browser.conftest import COACH, PASSWORD, sign_in

pytestmark = pytest.mark.browser


def _new_performer(server, key: str, name: str) -> None:
    from app import crud

    with server.sessions()() as s:
        u = crud.create_user(
            s, club_id=server.club_id, role="performer", email=f"{key}@example.com",
            display_name=name, password=PASSWORD,
        )  # fmt: skip
        server.performers[key] = u.id


def test_a_performer_opens_compares_and_deletes_their_attempts(
    server, browser, clip, clip_result, shots
):
    _new_performer(server, "mia", "Mia Mashie")
    older = server.add_done_analysis("mia", clip, clip_result)
    newer = server.add_done_analysis("mia", clip, clip_result)
    ctx = browser.new_context(viewport={"width": 1280, "height": 800})
    page = ctx.new_page()
    sign_in(page, server.url, "mia@example.com")
    assert page.url.endswith("/analyses")
    rows = page.locator("#attempts-table tbody tr")
    assert rows.count() == 2
    assert rows.first.get_attribute("data-id") == newer  # newest first
    page.wait_for_function(
        "() => Array.from(document.querySelectorAll('img.thumb'))"
        ".every(i => i.naturalWidth === 160)"
    )
    assert "°" in rows.first.locator("td").nth(3).inner_text()  # the headline error
    page.screenshot(path=str(shots / "my-analyses.png"), full_page=True)

    compare = page.get_by_role("button", name="Compare the two ticked")
    assert compare.is_disabled()
    for box in page.locator("input.pick").all():
        box.check()
    assert compare.is_enabled()
    compare.click()
    page.wait_for_url(f"**/compare?a={older}&b={newer}")
    page.go_back()

    page.once("dialog", lambda d: d.accept())
    page.locator(f"tr[data-id='{newer}'] button.delete").click()
    page.wait_for_function(
        "() => document.querySelectorAll('#attempts-table tbody tr').length === 1"
    )
    assert page.request.get(f"{server.url}/api/v1/analyses/{newer}").status == 404
    ctx.close()

    phone = browser.new_context(viewport={"width": 390, "height": 844}, is_mobile=True)
    page = phone.new_page()
    sign_in(page, server.url, "mia@example.com")
    assert page.evaluate("document.documentElement.scrollWidth") <= 390 + 1
    page.screenshot(path=str(shots / "my-analyses-phone.png"), full_page=True)
    phone.close()


def test_a_coach_works_through_the_to_review_list(server, browser, clip, clip_result, shots):
    aid = server.add_done_analysis("olive", clip, clip_result)
    ctx = browser.new_context(viewport={"width": 1280, "height": 900})
    page = ctx.new_page()
    sign_in(page, server.url, COACH[0], COACH[1], next_path="/dashboard?review=to_review")
    assert page.locator(f"a[href='/analyses/{aid}/review']").count() == 1
    page.screenshot(path=str(shots / "dashboard-to-review.png"), full_page=True)
    page.locator(f"a[href='/analyses/{aid}/review']").click()
    page.get_by_role("button", name="Mark reviewed").click()
    page.get_by_text("Reviewed on").wait_for()
    page.goto(f"{server.url}/dashboard?review=to_review")
    assert page.locator(f"a[href='/analyses/{aid}/review']").count() == 0
    page.goto(f"{server.url}/dashboard?review=reviewed")
    assert page.locator(f"a[href='/analyses/{aid}/review']").count() == 1
    ctx.close()
