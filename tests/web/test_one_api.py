"""One API for clubs and pages: an API key or a session cookie, each scoped to what it may see."""

from __future__ import annotations

from app import crud
from tests.app.conftest import SAMPLE_VIDEO
from tests.web.test_pages import add_done, env, sign_in  # noqa: F401 - env is a fixture


def api_key(app, club_id: int) -> dict[str, str]:
    with app.state.sessionmaker() as s:
        _, key = crud.create_api_key(s, club_id=club_id, name="club app")
        s.commit()
    return {"X-API-Key": key}


def test_nobody_gets_nothing(env):  # noqa: F811
    app, client, ids, _, settings = env
    add_done(app, settings, ids, ids["perf"])
    for path in ("/api/v1/analyses", "/api/v1/references", f"/api/v1/performers/{ids['perf']}"
                 "/history"):  # fmt: skip
        r = client.get(path)
        assert r.status_code == 401, path
        assert r.json()["error"]["code"] == "unauthorized"


def test_a_key_and_a_coach_session_read_the_same_rows(env):  # noqa: F811
    app, client, ids, _, settings = env
    mine, theirs = (
        add_done(app, settings, ids, ids["perf"]),
        add_done(app, settings, ids, ids["other"]),
    )
    key = api_key(app, ids["club"])
    by_key = client.get("/api/v1/analyses", headers=key).json()
    sign_in(client, "c@a.org")
    by_coach = client.get("/api/v1/analyses").json()
    assert (
        {a["id"] for a in by_key["items"]} == {mine, theirs} == {a["id"] for a in by_coach["items"]}
    )
    for path in (f"/api/v1/analyses/{mine}/summary", f"/api/v1/references/{ids['ref']}"):
        assert client.get(path).json() == client.get(path, headers=key).json(), path


def test_a_performer_sees_and_does_only_their_own(env):  # noqa: F811
    app, client, ids, queue, settings = env
    mine, theirs = (
        add_done(app, settings, ids, ids["perf"]),
        add_done(app, settings, ids, ids["other"]),
    )
    sign_in(client, "p@a.org")
    assert [a["id"] for a in client.get("/api/v1/analyses").json()["items"]] == [mine]
    # asking for another performer's list gives nothing, not theirs
    other = client.get("/api/v1/analyses", params={"performer_id": ids["other"]}).json()
    assert other["items"] == [] and other["total"] == 0
    for path in (f"/api/v1/analyses/{theirs}", f"/api/v1/analyses/{theirs}/export.csv",
                 f"/api/v1/analyses/{theirs}/comments",
                 f"/api/v1/performers/{ids['other']}/history"):  # fmt: skip
        assert client.get(path).status_code == 404, path
    assert client.get(f"/api/v1/performers/{ids['perf']}/history").status_code == 200
    # a coach's powers are refused with 403
    assert client.put(f"/api/v1/analyses/{mine}/reviewed").status_code == 403
    # their own attempts are theirs to delete; another's is not even seen
    assert client.delete(f"/api/v1/analyses/{theirs}").status_code == 404
    assert client.get("/api/v1/club").status_code == 403
    assert client.post("/api/v1/invites", json={}).status_code == 403
    r = client.put(f"/api/v1/references/{ids['ref']}/domain", json={"segment_names": []})
    assert r.status_code == 403
    # an upload is always for themselves, whatever performer_id says
    with open(SAMPLE_VIDEO, "rb") as f:
        r = client.post("/api/v1/analyses",
                        data={"reference_id": ids["ref"], "performer_id": ids["other"]},
                        files={"video": ("clip.mp4", f, "video/mp4")})  # fmt: skip
    assert r.status_code == 201, r.text
    assert r.json()["performer_id"] == ids["perf"] and queue.jobs
    assert client.delete(f"/api/v1/analyses/{mine}").status_code == 204
    assert client.get(f"/api/v1/analyses/{mine}").status_code == 404


def test_an_upload_must_say_whom_it_shows(env):  # noqa: F811
    app, client, ids, queue, _ = env
    key = api_key(app, ids["club"])
    with open(SAMPLE_VIDEO, "rb") as f:
        r = client.post("/api/v1/analyses", headers=key, data={"reference_id": ids["ref"]},
                        files={"video": ("clip.mp4", f, "video/mp4")})  # fmt: skip
    assert r.status_code == 422 and "performer" in r.json()["error"]["message"]
    sign_in(client, "c@a.org")
    with open(SAMPLE_VIDEO, "rb") as f:
        r = client.post("/api/v1/analyses",
                        data={"reference_id": ids["ref"], "performer_id": ids["coach"]},
                        files={"video": ("clip.mp4", f, "video/mp4")})  # fmt: skip
    assert r.status_code == 422
    assert queue.jobs == []


def test_comments_are_written_by_people(env):  # noqa: F811
    app, client, ids, _, settings = env
    aid = add_done(app, settings, ids, ids["perf"])
    key = api_key(app, ids["club"])
    base = f"/api/v1/analyses/{aid}/comments"
    assert client.post(base, headers=key, json={"body": "hi"}).status_code == 403
    sign_in(client, "p@a.org")
    assert client.post(base, json={"body": "my knee?"}).status_code == 201
    listed = client.get(base, headers=key).json()
    assert [c["body"] for c in listed["items"]] == ["my knee?"]
    assert listed["total"] == 1
