"""The API docs and the site's icon work with no network: nothing comes from a CDN."""


def test_api_docs_load_their_assets_from_the_service(client):
    page = client.get("/api/v1/docs")
    assert page.status_code == 200
    html = page.text
    assert "/api/v1/docs-assets/swagger-ui-bundle.js" in html and "/api/v1/openapi.json" in html
    assert "cdn." not in html and "https://" not in html
    js = client.get("/api/v1/docs-assets/swagger-ui-bundle.js")
    assert js.status_code == 200 and len(js.content) > 100_000
    assert client.get("/api/v1/docs-assets/swagger-ui.css").status_code == 200


def test_the_favicon_is_served(client):
    r = client.get("/favicon.ico", follow_redirects=False)
    assert r.status_code == 301 and r.headers["location"] == "/static/favicon.svg"
    icon = client.get("/static/favicon.svg")
    assert icon.status_code == 200 and icon.text.startswith("<svg")
