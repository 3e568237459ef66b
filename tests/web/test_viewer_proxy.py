"""The 3D view's relay refuses what it must before it relays anything: other sites, callers
who are not signed in, other people's analyses, malformed tab tokens."""

from __future__ import annotations

import pytest
from starlette.websockets import WebSocketDisconnect

from tests.web.test_pages import add_done, env, sign_in  # noqa: F401 - env is a fixture

TAB = "0123456789abcdef0123456789abcdef"


def _refused(client, path: str, **headers) -> int:
    with pytest.raises(WebSocketDisconnect) as e, client.websocket_connect(path, headers=headers):
        pass
    return e.value.code


def test_the_relay_refuses_before_relaying(env):  # noqa: F811
    app, client, ids, _, settings = env
    mine = add_done(app, settings, ids, ids["perf"])
    theirs = add_done(app, settings, ids, ids["other"])
    assert client.get(f"/analyses/{mine}/3d/{TAB}/").status_code == 401
    assert _refused(client, f"/analyses/{mine}/3d/{TAB}") == 4401
    sign_in(client, "p@a.org")
    # a page on another site cannot open the view with this browser's cookie
    assert _refused(client, f"/analyses/{mine}/3d/{TAB}", origin="https://evil.example") == 4403
    assert _refused(client, f"/analyses/{theirs}/3d/{TAB}") == 4404
    assert client.get(f"/analyses/{theirs}/3d/{TAB}/").status_code == 404
    assert client.get(f"/analyses/{mine}/3d/not-a-token/").status_code == 404
    # signed in and allowed, but no viewer started yet: said so
    r = client.get(f"/analyses/{mine}/3d/{TAB}/")
    assert r.status_code == 409 and "not started" in r.json()["error"]["message"]
