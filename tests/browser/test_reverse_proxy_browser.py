"""The app behind a reverse proxy with HTTPS (Debian's nginx, started by the test): the result
page and its 3D view load through the proxy's origin, the view's websocket included."""

from __future__ import annotations

import shutil
import subprocess
import time
import urllib.request
from pathlib import Path

import pytest

from tests.browser.conftest import _free_port, sign_in
from tests.browser.test_experience_browser import _pixels, _skeleton_box
from tests.browser.test_pages_browser import wait_results

pytestmark = pytest.mark.browser

NGINX = shutil.which("nginx") or "/usr/sbin/nginx"

CONF = """
daemon off;
master_process off;
worker_processes 1;
pid {d}/nginx.pid;
error_log {d}/error.log warn;
events {{ worker_connections 256; }}
http {{
  access_log off;
  client_body_temp_path {d}/body;
  proxy_temp_path {d}/proxy;
  fastcgi_temp_path {d}/fastcgi;
  uwsgi_temp_path {d}/uwsgi;
  scgi_temp_path {d}/scgi;
  client_max_body_size 300m;
  map $http_upgrade $connection_upgrade {{ default upgrade; '' close; }}
  server {{
    listen 127.0.0.1:{port} ssl;
    ssl_certificate {d}/cert.pem;
    ssl_certificate_key {d}/key.pem;
    location / {{
      proxy_pass {upstream};
      proxy_http_version 1.1;
      proxy_set_header Upgrade $http_upgrade;
      proxy_set_header Connection $connection_upgrade;
      proxy_set_header Host $http_host;
      proxy_set_header X-Forwarded-Proto https;
      proxy_read_timeout 300s;
    }}
  }}
}}
"""


@pytest.fixture(scope="module")
def https_url(server, tmp_path_factory):
    """``https://127.0.0.1:PORT``: nginx with a self-signed certificate in front of the app."""
    if not Path(NGINX).exists():
        pytest.skip("Debian's nginx is not installed (scripts/install-system.sh installs it)")
    d = tmp_path_factory.mktemp("nginx")
    subprocess.run(
        ["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1",
         "-subj", "/CN=127.0.0.1", "-keyout", str(d / "key.pem"), "-out", str(d / "cert.pem")],
        check=True, capture_output=True,
    )  # fmt: skip
    port = _free_port()
    (d / "nginx.conf").write_text(CONF.format(d=d, port=port, upstream=server.url))
    proc = subprocess.Popen([NGINX, "-p", str(d), "-c", str(d / "nginx.conf")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)  # fmt: skip
    url = f"https://127.0.0.1:{port}"
    import ssl

    insecure = ssl.create_default_context()
    insecure.check_hostname, insecure.verify_mode = False, ssl.CERT_NONE
    deadline = time.monotonic() + 20
    while True:
        try:
            with urllib.request.urlopen(f"{url}/api/v1/health", timeout=2, context=insecure):
                break
        except OSError:
            if proc.poll() is not None or time.monotonic() > deadline:
                proc.kill()
                log = (d / "error.log").read_text() if (d / "error.log").exists() else ""
                raise RuntimeError(f"nginx did not start:\n{log}") from None
            time.sleep(0.2)
    yield url
    proc.terminate()
    proc.wait(timeout=10)


def test_the_3d_view_loads_through_the_apps_origin_behind_https(
    server, browser, clip, clip_result, https_url
):
    aid = server.add_done_analysis("pat", clip, clip_result)
    ctx = browser.new_context(viewport={"width": 1280, "height": 900}, ignore_https_errors=True)
    page = ctx.new_page()
    sockets = []
    page.on("websocket", lambda ws: sockets.append(ws.url))
    sign_in(page, https_url, "pat@example.com", next_path=f"/analyses/{aid}")
    wait_results(page)
    page.wait_for_selector("#viewer3d:not([hidden]), #fallback3d:not([hidden])", timeout=30_000)
    assert page.locator("#viewer3d").is_visible(), page.locator("#viewer-status").inner_text()
    src = page.locator("#viewer3d").get_attribute("src")
    assert src.startswith(f"/analyses/{aid}/3d/")  # same origin: the proxy's, over HTTPS
    frame = page.frame_locator("#viewer3d")
    frame.locator("canvas").first.wait_for(timeout=20_000)
    page.wait_for_timeout(2500)
    assert any(u.startswith(f"wss://127.0.0.1:{https_url.rsplit(':', 1)[1]}/analyses/{aid}/3d/")
               for u in sockets), sockets  # fmt: skip
    count, height, _ = _skeleton_box(_pixels(page.locator("#viewer3d").screenshot()))
    assert count > 2000 and height > 0.4, (count, height)  # the coloured skeleton is drawn
    ctx.close()
