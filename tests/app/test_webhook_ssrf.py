"""Webhooks go only to public addresses, signed with a timestamp (issue 26 item 8).

A club's webhook URL pointing at the service's own network (loopback, cloud metadata,
private ranges, in any spelling of the address) is refused when it is set (422) and again
when a delivery is sent: no request reaches a loopback listener unless the operator allows
private addresses. Every case also runs with ``webhook_allow_private`` on, where the same
request does arrive, so the refusal is the check's doing and not a dead address.
"""

from __future__ import annotations

import json
import socket
import threading
import time
import uuid
from collections.abc import Iterator
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, HTTPServer

import pytest

from app.core import webhooks
from app.core.config import Settings
from app.core.reflect import Notifier
from app.core.security import WEBHOOK_TOLERANCE_S, sign_webhook, verify_webhook

SECRET = "whsec_test"

#: Internal addresses, as a club might spell them.
INTERNAL_URLS = [
    "http://127.0.0.1/hook",
    "http://169.254.169.254/latest/meta-data/",
    "http://10.0.0.1/",
    "http://192.168.1.10:8080/",
    "http://[::1]/",
    "http://0.0.0.0/",
    "http://2130706433/",  # 127.0.0.1 as one integer
    "http://0x7f.0.0.1/",  # hex
    "http://0177.0.0.1/",  # octal
    "http://[::ffff:127.0.0.1]/",  # IPv4-mapped IPv6
    "http://[::ffff:a9fe:a9fe]/",  # 169.254.169.254, mapped
    "http://224.0.0.1/",  # multicast (ipaddress calls it global)
    "http://100.64.0.1/",  # carrier-grade NAT
    "http://[fe80::1]/",
    "http://[fc00::1]/",
    "http://localhost/",
]


class FakeDns:
    """``socket.getaddrinfo`` with some names pointed at chosen addresses (the rest real)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.names: dict[str, str] = {}
        self._real = socket.getaddrinfo
        monkeypatch.setattr(socket, "getaddrinfo", self)

    def __call__(self, host, port, *args, **kwargs):
        if host in self.names:
            ip = self.names[host]
            family = socket.AF_INET6 if ":" in ip else socket.AF_INET
            return [(family, socket.SOCK_STREAM, 6, "", (ip, port))]
        return self._real(host, port, *args, **kwargs)


@pytest.fixture
def dns(monkeypatch) -> FakeDns:
    return FakeDns(monkeypatch)


@dataclass
class Listener:
    """An HTTP server on a loopback address that records every request it gets."""

    host: str
    status: int = 204
    headers: dict[str, str] = field(default_factory=dict)
    fail_first: int = 0
    received: list[tuple[dict[str, str], bytes]] = field(default_factory=list)
    port: int = 0

    def handler(self) -> type[BaseHTTPRequestHandler]:
        listener = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self):  # noqa: N802
                body = self.rfile.read(int(self.headers.get("Content-Length") or 0))
                listener.received.append((dict(self.headers), body))
                if listener.fail_first > 0:
                    listener.fail_first -= 1
                    self.send_response(503)
                else:
                    self.send_response(listener.status)
                for k, v in listener.headers.items():
                    self.send_header(k, v)
                self.send_header("Content-Length", "0")
                self.end_headers()

            def log_message(self, *args):
                pass

        return Handler


@pytest.fixture
def listen() -> Iterator:
    servers: list[HTTPServer] = []

    def start(host: str = "127.0.0.1", **kwargs) -> Listener:
        listener = Listener(host, **kwargs)

        class Server(HTTPServer):
            address_family = socket.AF_INET6 if ":" in host else socket.AF_INET

        try:
            server = Server((host, 0), listener.handler())
        except OSError:
            pytest.skip(f"cannot listen on {host}")
        listener.port = server.server_address[1]
        threading.Thread(target=server.serve_forever, daemon=True).start()
        servers.append(server)
        return listener

    yield start
    for s in servers:
        s.shutdown()
        s.server_close()


def notifier(tmp_path, *, allow_private: bool, attempts: int = 2) -> Notifier:
    settings = Settings(
        data_dir=tmp_path / "data", webhook_allow_private=allow_private,
        webhook_attempts=attempts, webhook_backoff_s=0.01, webhook_timeout_s=2,
    )  # fmt: skip
    return Notifier(settings, session_factory=None)


def deliver(n: Notifier, url: str, delivery_id: str = "d-1") -> bool:
    return n.deliver(url, SECRET, b'{"event":"analysis.done"}', "a-1", delivery_id)


# ---- when the URL is set


@pytest.mark.parametrize("url", INTERNAL_URLS)
def test_an_internal_webhook_url_is_refused_when_set(client, club, url):
    r = client.patch("/api/v1/club", headers=club.headers, json={"webhook_url": url})
    assert r.status_code == 422, r.text
    error = r.json()["error"]
    assert error["code"] == "invalid_request"
    assert error["message"].startswith("webhook_url: ") and "public" in error["message"]
    [problem] = error["details"]["errors"]
    assert problem["loc"] == "body.webhook_url" and problem["type"] == "webhook_url_refused"
    assert client.get("/api/v1/club", headers=club.headers).json()["webhook_url"] is None


@pytest.mark.parametrize(
    "url", ["ftp://example.com/hook", "file:///etc/passwd", "gopher://127.0.0.1:6379/_", "x"]
)
def test_only_http_and_https_urls_are_accepted(client, club, url):
    r = client.patch("/api/v1/club", headers=club.headers, json={"webhook_url": url})
    assert r.status_code == 422
    assert r.json()["error"]["details"]["errors"][0]["loc"] == "body.webhook_url"


def test_a_name_that_resolves_to_an_internal_address_is_refused(client, club, dns):
    dns.names["hooks.example.test"] = "10.1.2.3"
    r = client.patch(
        "/api/v1/club", headers=club.headers, json={"webhook_url": "https://hooks.example.test/x"}
    )
    assert r.status_code == 422
    assert "resolves to 10.1.2.3" in r.json()["error"]["message"]


def test_a_name_with_any_internal_address_is_refused(monkeypatch, client, club):
    """One public and one private address: the delivery could reach either."""
    real = socket.getaddrinfo

    def two(host, port, *args, **kwargs):
        if host != "split.example.test":
            return real(host, port, *args, **kwargs)
        return [(socket.AF_INET, socket.SOCK_STREAM, 6, "", (ip, port))
                for ip in ("93.184.216.34", "127.0.0.1")]  # fmt: skip

    monkeypatch.setattr(socket, "getaddrinfo", two)
    r = client.patch(
        "/api/v1/club", headers=club.headers, json={"webhook_url": "http://split.example.test/"}
    )
    assert r.status_code == 422


def test_a_public_url_is_accepted_and_an_unresolvable_one_refused(client, club, dns):
    dns.names["hooks.example.test"] = "93.184.216.34"
    url = "https://hooks.example.test/coach"
    r = client.patch("/api/v1/club", headers=club.headers, json={"webhook_url": url})
    assert r.status_code == 200, r.text
    assert r.json()["webhook_url"] == url and r.json()["webhook_secret"]
    r = client.patch(
        "/api/v1/club", headers=club.headers, json={"webhook_url": "http://nothing.invalid/"}
    )
    assert r.status_code == 422 and "cannot be resolved" in r.json()["error"]["message"]


@pytest.mark.settings(webhook_allow_private=True)
def test_the_operator_can_allow_private_addresses(client, club):
    r = client.patch(
        "/api/v1/club", headers=club.headers, json={"webhook_url": "http://127.0.0.1:9/hook"}
    )
    assert r.status_code == 200, r.text
    r = client.patch("/api/v1/club", headers=club.headers, json={"webhook_url": "ftp://127.0.0.1/"})
    assert r.status_code == 422  # the scheme is checked regardless


# ---- when a delivery is sent


@pytest.mark.parametrize("allow_private", [False, True])
def test_no_delivery_reaches_a_loopback_listener(tmp_path, listen, dns, allow_private):
    listener = listen("127.0.0.1")
    dns.names["rebound.example.test"] = "127.0.0.1"  # public when set, loopback now
    p = listener.port
    # (An octal spelling is normalised when the URL is set and httpx refuses it as stored.)
    urls = [
        f"http://127.0.0.1:{p}/", f"http://2130706433:{p}/", f"http://0x7f.0.0.1:{p}/",
        f"http://0.0.0.0:{p}/", f"http://[::ffff:127.0.0.1]:{p}/", f"http://localhost:{p}/",
        f"http://rebound.example.test:{p}/",
    ]  # fmt: skip
    n = notifier(tmp_path, allow_private=allow_private)
    results = {url: deliver(n, url) for url in urls}
    if allow_private:  # the control: each of these URLs does reach the listener
        assert all(results.values()), results
        assert len(listener.received) == len(urls)
    else:
        assert not any(results.values()), results
        assert listener.received == []


@pytest.mark.parametrize("allow_private", [False, True])
def test_no_delivery_reaches_an_ipv6_loopback_listener(tmp_path, listen, allow_private):
    listener = listen("::1")
    delivered = deliver(notifier(tmp_path, allow_private=allow_private),
                        f"http://[::1]:{listener.port}/")  # fmt: skip
    assert delivered is allow_private
    assert len(listener.received) == (1 if allow_private else 0)


@pytest.mark.parametrize(
    "url",
    ["http://169.254.169.254/latest/meta-data/", "http://10.0.0.1/", "http://metadata.test/",
     "http://intranet.test/", "http://[::ffff:a9fe:a9fe]/"],
)  # fmt: skip
def test_no_request_is_sent_to_an_internal_address(tmp_path, monkeypatch, dns, url):
    dns.names |= {"metadata.test": "169.254.169.254", "intranet.test": "10.0.0.1"}
    sent = []
    monkeypatch.setattr(webhooks, "post", lambda *a, **k: sent.append(a))
    assert deliver(notifier(tmp_path, allow_private=False, attempts=3), url) is False
    assert sent == []


def test_a_name_rebound_to_loopback_after_it_was_set_gets_nothing(client, app, club, dns, listen):
    """Checked at set time (public then), checked again at delivery (loopback now)."""
    listener = listen("127.0.0.1")
    dns.names["hooks.example.test"] = "93.184.216.34"
    url = f"http://hooks.example.test:{listener.port}/hook"
    r = client.patch("/api/v1/club", headers=club.headers, json={"webhook_url": url})
    assert r.status_code == 200
    dns.names["hooks.example.test"] = "127.0.0.1"
    assert app.state.notifier.deliver(url, SECRET, b"{}", "a-1", "d-1") is False
    assert listener.received == []


def test_a_delivery_connects_to_the_address_it_checked(tmp_path, listen, dns):
    """The request goes to the resolved address with the URL's own name as its Host."""
    listener = listen("127.0.0.1")
    dns.names["pinned.example.test"] = "127.0.0.1"
    url = f"http://pinned.example.test:{listener.port}/hook"
    assert deliver(notifier(tmp_path, allow_private=True), url)
    [(headers, _)] = listener.received
    assert headers["Host"] == f"pinned.example.test:{listener.port}"


def test_a_redirect_is_not_followed_nor_retried(tmp_path, listen):
    target = listen("127.0.0.1")
    redirecting = listen(
        "127.0.0.1", status=307, headers={"Location": f"http://127.0.0.1:{target.port}/"}
    )
    n = notifier(tmp_path, allow_private=True, attempts=3)
    assert deliver(n, f"http://127.0.0.1:{redirecting.port}/") is False
    assert len(redirecting.received) == 1 and target.received == []


# ---- signatures


def test_a_delivery_is_signed_with_its_timestamp_and_keeps_its_id_across_retries(tmp_path, listen):
    listener = listen("127.0.0.1", fail_first=1)
    body = json.dumps({"delivery_id": "d-42", "event": "analysis.done"}).encode()
    n = notifier(tmp_path, allow_private=True, attempts=3)
    before = time.time()
    assert n.deliver(f"http://127.0.0.1:{listener.port}/", SECRET, body, "a-1", "d-42")
    assert len(listener.received) == 2  # the 503, then the retry
    for headers, got in listener.received:
        assert got == body and headers["X-Coach-Delivery"] == "d-42"
        timestamp = headers["X-Coach-Timestamp"]
        assert before - 1 <= int(timestamp) <= time.time() + 1
        assert verify_webhook(got, SECRET, headers["X-Coach-Signature"], timestamp)
        assert not verify_webhook(got, "whsec_other", headers["X-Coach-Signature"], timestamp)


def test_verify_round_trip_and_tampering():
    body, ts = b'{"event":"analysis.done"}', int(time.time())
    sig = sign_webhook(body, SECRET, ts)
    assert sig.startswith("sha256=") and len(sig) == 7 + 64
    assert verify_webhook(body, SECRET, sig, ts)
    assert verify_webhook(body, SECRET, sig, str(ts))  # as the header carries it
    assert not verify_webhook(body + b" ", SECRET, sig, ts)
    assert not verify_webhook(body, SECRET, sig, ts - 1)  # the timestamp is signed
    assert sign_webhook(body, SECRET, ts) != sign_webhook(body, SECRET, ts + 1)
    for bad in ("", "soon", "1.5e9", "9" * 5000):
        assert not verify_webhook(body, SECRET, sig, bad)


def test_a_replayed_delivery_is_refused_after_the_tolerance():
    body, ts = b"{}", 1_700_000_000
    sig = sign_webhook(body, SECRET, ts)
    assert WEBHOOK_TOLERANCE_S == 300
    assert verify_webhook(body, SECRET, sig, ts, now=ts + 299)
    assert not verify_webhook(body, SECRET, sig, ts, now=ts + 301)  # replayed later
    assert not verify_webhook(body, SECRET, sig, ts, now=ts - 301)  # from the future
    assert not verify_webhook(body, SECRET, sig, ts, now=ts + 11, tolerance_s=10)
    assert verify_webhook(body, SECRET, sig, ts, now=ts + 3000, tolerance_s=3600)
    old = int(time.time()) - 3600  # the default clock: an hour-old capture
    assert not verify_webhook(body, SECRET, sign_webhook(body, SECRET, old), old)


def test_the_route_documents_the_signature(client):
    doc = client.get("/api/v1/openapi.json").json()["paths"]["/api/v1/club"]["patch"]
    for words in ("X-Coach-Delivery", "X-Coach-Timestamp", '"<X-Coach-Timestamp>.<body>"',
                  "public"):  # fmt: skip
        assert words in doc["description"], words


def test_delivery_ids_are_uuids(client, app, club_ref, queue, video_file, monkeypatch, dns):
    """The notifier puts a fresh delivery id in the body and the header."""
    from tests.app.conftest import upload
    from worker.contract import AnalysisFolder

    dns.names["hooks.example.test"] = "93.184.216.34"
    r = client.patch(
        "/api/v1/club", headers=club_ref.headers,
        json={"webhook_url": "https://hooks.example.test/x"},
    )  # fmt: skip
    assert r.status_code == 200
    sent = []
    monkeypatch.setattr(app.state.notifier, "deliver", lambda *a: sent.append(a))
    a = upload(client, club_ref, video_file).json()
    folder = AnalysisFolder(queue.jobs[0].work_dir)
    folder.status.write_text(json.dumps({"state": "failed", "error": "boom"}))
    client.get(f"/api/v1/analyses/{a['id']}", headers=club_ref.headers)
    app.state.notifier.wait(timeout=5)
    [(url, _, body, analysis_id, delivery_id)] = sent
    assert url == "https://hooks.example.test/x" and analysis_id == a["id"]
    assert str(uuid.UUID(delivery_id)) == delivery_id
    assert json.loads(body)["delivery_id"] == delivery_id
