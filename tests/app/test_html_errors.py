"""Browsers get an HTML page for an unknown address; the API and scripts get JSON."""


def test_an_unknown_page_is_html_for_a_browser_and_json_otherwise(client):
    browser = {"Accept": "text/html,application/xhtml+xml,*/*;q=0.8"}
    page = client.get("/no-such-page", headers=browser)
    assert page.status_code == 404 and page.headers["content-type"].startswith("text/html")
    assert "Not found" in page.text and "There is no page at this address." in page.text
    plain = client.get("/no-such-page")
    assert plain.status_code == 404 and plain.json()["error"]["code"] == "not_found"
    api = client.get("/api/v1/no-such-route", headers=browser)
    assert api.status_code == 404 and api.json()["error"]["code"] == "not_found"
