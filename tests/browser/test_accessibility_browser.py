"""Accessibility of every page, checked by axe-core (4.12, the npm package's build, as
shipped inside the axe-playwright-python wheel) in real Chromium: no serious or critical
violation, desktop and phone width."""

from __future__ import annotations

import pytest

from tests.browser.conftest import COACH, sign_in
from tests.browser.test_pages_browser import wait_results

pytestmark = pytest.mark.browser

#: What a page must be free of (axe's impact levels "minor" and "moderate" are reported by
#: the message but do not fail).
BLOCKING = ("serious", "critical")


def _violations(page) -> list[str]:
    from axe_playwright_python.sync_playwright import Axe

    # The 3D view's frame is viser's page (a third-party client): its own accessibility is
    # out of this project's hands, so axe looks at ours only.
    results = Axe().run(page, context={"exclude": [["iframe"]]})
    return [
        f"{v['impact']}: {v['id']} ({v['help']}) at "
        + ", ".join(n["target"][0] if isinstance(n["target"][0], str) else str(n["target"])
                    for n in v["nodes"][:3])
        for v in results.response["violations"]
        if v.get("impact") in BLOCKING
    ]  # fmt: skip


@pytest.mark.parametrize("width", [1280, 390])
def test_pages_have_no_serious_accessibility_violations(server, browser, clip, clip_result,
                                                        width, shots):  # fmt: skip
    """Each page is also kept as a screenshot at this width (``page-<name>-<width>.png``)."""
    aid = server.add_done_analysis("pat", clip, clip_result)
    found: dict[str, list[str]] = {}

    def check(name: str) -> None:
        found[name] = _violations(page)
        slug = name.strip("/").replace("/", "-").replace("{id}", "id") or "home"
        page.screenshot(path=str(shots / f"page-{slug}-{width}.png"), full_page=True)

    ctx = browser.new_context(viewport={"width": width, "height": 900})
    page = ctx.new_page()
    page.goto(f"{server.url}/login")
    check("/login")
    sign_in(page, server.url, "pat@example.com", next_path="/analyses")
    check("/analyses")
    page.goto(f"{server.url}/upload")
    page.wait_for_selector(".ref-option")
    check("/upload")
    page.goto(f"{server.url}/analyses/{aid}")
    wait_results(page)
    check("/analyses/{id}")
    page.goto(f"{server.url}/captures")
    check("/captures")
    other = server.add_done_analysis("pat", clip, clip_result)
    page.goto(f"{server.url}/performers/{server.performers['pat']}/compare?a={aid}&b={other}")
    page.wait_for_selector("#compare[data-ready=true]", state="attached")
    check("/performers/{id}/compare")
    ctx.close()
    ctx = browser.new_context(viewport={"width": width, "height": 900})
    page = ctx.new_page()
    sign_in(page, server.url, COACH[0], COACH[1], next_path="/dashboard")
    check("/dashboard")
    page.goto(f"{server.url}/analyses/{aid}/review")
    wait_results(page)
    check("/analyses/{id}/review")
    page.goto(f"{server.url}/references")
    page.wait_for_selector(".ref-card")
    check("/references")
    page.goto(f"{server.url}/analyses/{aid}/report")
    check("/analyses/{id}/report")
    ctx.close()
    bad = [f"{path}: {v}" for path, vs in found.items() for v in vs]
    assert not bad, "\n".join(bad)
