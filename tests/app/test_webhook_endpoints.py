"""Webhook endpoints per club with event filters (issue 26 item 12).

A club keeps its default webhook (``PATCH /club``, every event) and may add endpoints at
``/api/v1/webhooks`` that receive only the events they name, each signed with its own secret.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, HTTPServer
from pathlib import Path
from typing import get_args

import pytest

from app.core.security import verify_webhook
from app.models import WEBHOOK_EVENTS
from app.schemas import WebhookEvent
from tests.app.conftest import make_club, upload
from tests.app.test_analyses import RESULT, write_atomic
from tests.app.test_webhook_ssrf import FakeDns

EVENTS = ["analysis.done", "analysis.failed", "analysis.cancelled"]


@dataclass
class Receiver:
    """A loopback HTTP server recording (path, headers, body) of every POST."""

    url: str = ""
    received: list[tuple[str, dict[str, str], bytes]] = field(default_factory=list)

    def on(self, path: str) -> list[tuple[dict[str, str], bytes]]:
        return [(h, b) for p, h, b in self.received if p == path]


@pytest.fixture
def receiver() -> Iterator[Receiver]:
    rec = Receiver()

    class Handler(BaseHTTPRequestHandler):
        def do_POST(self):  # noqa: N802
            body = self.rfile.read(int(self.headers["Content-Length"]))
            rec.received.append((self.path, dict(self.headers), body))
            self.send_response(204)
            self.end_headers()

        def log_message(self, *args):
            pass

    server = HTTPServer(("127.0.0.1", 0), Handler)
    rec.url = f"http://127.0.0.1:{server.server_port}"
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield rec
    server.shutdown()
    server.server_close()


def create(client, club, **body):
    return client.post("/api/v1/webhooks", headers=club.headers, json=body)


def test_the_documented_events_are_the_ones_sent():
    assert list(get_args(WebhookEvent)) == list(WEBHOOK_EVENTS) == EVENTS


@pytest.mark.settings(webhook_allow_private=True)
def test_an_endpoint_is_created_read_changed_and_removed(client, club):
    r = create(client, club, url="HTTP://127.0.0.1:9/Hook", description="scores")
    assert r.status_code == 201, r.text
    made = r.json()
    assert r.headers["Location"] == f"/api/v1/webhooks/{made['id']}"
    assert made["url"] == "http://127.0.0.1:9/Hook" and made["events"] == EVENTS
    assert made["description"] == "scores" and made["disabled_at"] is None
    assert made["secret"].startswith("whsec_")

    read = client.get(r.headers["Location"], headers=club.headers).json()
    assert "secret" not in read and read == {k: v for k, v in made.items() if k != "secret"}
    page = client.get("/api/v1/webhooks?limit=1", headers=club.headers).json()
    assert page == {"items": [read], "total": 1, "limit": 1, "offset": 0}

    path = f"/api/v1/webhooks/{made['id']}"
    r = client.patch(path, headers=club.headers,
                     json={"events": ["analysis.failed", "analysis.done", "analysis.done"]})
    assert r.status_code == 200, r.text
    assert r.json()["events"] == ["analysis.done", "analysis.failed"]  # deduplicated, in order
    assert r.json()["secret"] is None and r.json()["description"] == "scores"

    strict = client.patch(path, headers=club.headers, json={"rotate_secret": "yes"})
    assert strict.status_code == 422  # JSON true or false only
    rotated = client.patch(path, headers=club.headers, json={"rotate_secret": True}).json()
    assert rotated["secret"].startswith("whsec_") and rotated["secret"] != made["secret"]
    assert "secret" not in client.get(path, headers=club.headers).json()

    paused = client.patch(path, headers=club.headers, json={"enabled": False}).json()
    assert paused["disabled_at"] is not None
    resumed = client.patch(path, headers=club.headers, json={"enabled": True}).json()
    assert resumed["disabled_at"] is None

    assert client.delete(path, headers=club.headers).status_code == 204
    assert client.get(path, headers=club.headers).status_code == 404
    assert client.get("/api/v1/webhooks", headers=club.headers).json()["total"] == 0


@pytest.mark.settings(webhook_allow_private=True)
def test_another_club_cannot_see_or_touch_an_endpoint(client, app, club):
    made = create(client, club, url="http://127.0.0.1:9/").json()
    beta = make_club(app, "beta")
    path = f"/api/v1/webhooks/{made['id']}"
    assert client.get(path, headers=beta.headers).status_code == 404
    r = client.patch(path, headers=beta.headers, json={"rotate_secret": True})
    assert r.status_code == 404 and r.json()["error"]["code"] == "not_found"
    assert client.delete(path, headers=beta.headers).status_code == 404
    assert client.get("/api/v1/webhooks", headers=beta.headers).json()["total"] == 0
    assert client.get(path, headers=club.headers).status_code == 200  # still there


@pytest.mark.parametrize(
    "body",
    [
        {"url": "http://127.0.0.1:9/", "events": ["analysis.started"]},
        {"url": "http://127.0.0.1:9/", "events": []},
        {"url": "ftp://example.org/"},
        {"url": "http://127.0.0.1:9/", "secret": "mine"},
    ],
    ids=["unknown event", "no events", "not http", "unknown field"],
)
@pytest.mark.settings(webhook_allow_private=True)
def test_an_invalid_endpoint_is_refused(client, club, body):
    r = create(client, club, **body)
    assert r.status_code == 422, r.text
    assert r.json()["error"]["code"] == "invalid_request"


@pytest.mark.settings(webhook_allow_private=True)
def test_a_club_has_at_most_the_documented_number_of_endpoints(client, club):
    from app.api.routes.webhooks import MAX_ENDPOINTS

    for i in range(MAX_ENDPOINTS):
        assert create(client, club, url=f"http://127.0.0.1:9/{i}").status_code == 201
    r = create(client, club, url="http://127.0.0.1:9/one-more")
    assert r.status_code == 409, r.text
    assert r.json()["error"]["code"] == "limit_reached"
    listed = client.get("/api/v1/webhooks?limit=100", headers=club.headers).json()
    assert listed["total"] == MAX_ENDPOINTS


def test_an_internal_url_is_refused_when_set(client, club, monkeypatch):
    r = create(client, club, url="http://127.0.0.1/hook")
    assert r.status_code == 422
    [problem] = r.json()["error"]["details"]["errors"]
    assert problem["loc"] == "body.url" and problem["type"] == "webhook_url_refused"
    assert "loopback" in problem["message"]

    dns = FakeDns(monkeypatch)
    dns.names["hooks.example.test"] = "93.184.216.34"
    made = create(client, club, url="https://hooks.example.test/x")
    assert made.status_code == 201, made.text
    path = f"/api/v1/webhooks/{made.json()['id']}"
    r = client.patch(path, headers=club.headers, json={"url": "http://169.254.169.254/"})
    assert r.status_code == 422 and "link-local" in r.json()["error"]["message"]
    assert client.get(path, headers=club.headers).json()["url"] == "https://hooks.example.test/x"


def finish(client, club, queue, video_file, *, failed: bool) -> str:
    """Upload an analysis and let it end done (or failed); returns its id."""
    a = upload(client, club, video_file).json()
    folder = Path(queue.jobs[-1].work_dir)
    if failed:
        write_atomic(folder / "status.json", {"state": "failed", "error": "boom"})
    else:
        write_atomic(folder / "result.json", RESULT)
    client.get(f"/api/v1/analyses/{a['id']}", headers=club.headers)
    client.get(f"/api/v1/analyses/{a['id']}", headers=club.headers)  # no second send
    return a["id"]


@pytest.mark.settings(webhook_allow_private=True)  # the receiver listens on loopback
def test_an_endpoint_gets_only_the_events_it_names(
    client, app, club_ref, queue, video_file, receiver
):
    failed = create(client, club_ref, url=f"{receiver.url}/failed", events=["analysis.failed"])
    done = create(client, club_ref, url=f"{receiver.url}/done", events=["analysis.done"])
    analysis_id = finish(client, club_ref, queue, video_file, failed=False)
    app.state.notifier.wait(timeout=10)

    assert receiver.on("/failed") == []
    [(headers, body)] = receiver.on("/done")
    signature, timestamp = headers["X-Coach-Signature"], headers["X-Coach-Timestamp"]
    assert verify_webhook(body, done.json()["secret"], signature, timestamp)
    assert not verify_webhook(body, failed.json()["secret"], signature, timestamp)
    payload = json.loads(body)
    assert payload["event"] == "analysis.done" and payload["analysis"]["id"] == analysis_id
    assert payload["delivery_id"] == headers["X-Coach-Delivery"]


@pytest.mark.settings(webhook_allow_private=True)
def test_the_default_webhook_and_each_endpoint_get_their_own_delivery(
    client, app, club_ref, queue, video_file, receiver
):
    r = client.patch(
        "/api/v1/club", headers=club_ref.headers, json={"webhook_url": f"{receiver.url}/default"}
    )
    default_secret = r.json()["webhook_secret"]
    secrets = {
        p: create(client, club_ref, url=f"{receiver.url}{p}").json()["secret"]
        for p in ("/one", "/two", "/paused")
    }
    paused = client.get("/api/v1/webhooks?limit=3&offset=2", headers=club_ref.headers).json()
    client.patch(f"/api/v1/webhooks/{paused['items'][0]['id']}", headers=club_ref.headers,
                 json={"enabled": False})  # fmt: skip
    finish(client, club_ref, queue, video_file, failed=True)
    app.state.notifier.wait(timeout=10)

    assert receiver.on("/paused") == []
    ids = set()
    for path, secret in {"/default": default_secret, "/one": secrets["/one"],
                         "/two": secrets["/two"]}.items():  # fmt: skip
        [(headers, body)] = receiver.on(path)
        assert json.loads(body)["event"] == "analysis.failed", path
        signed = headers["X-Coach-Signature"], headers["X-Coach-Timestamp"]
        assert verify_webhook(body, secret, *signed), path
        ids.add(headers["X-Coach-Delivery"])
    assert len(ids) == 3  # one delivery id per receiver
