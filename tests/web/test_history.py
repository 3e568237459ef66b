"""My analyses (a performer's home) and the coach's review mark (issue 21, item 1)."""

from __future__ import annotations

import json
import re

import cv2
import numpy as np

from app.models import Analysis
from tests.web.test_pages import add_done, env, fake_result, sign_in  # noqa: F401 - env is a fixture


def _mean_error(doc: dict) -> float:
    errs = [f["posture_error_deg"] for f in doc["frames"]]
    return sum(errs) / len(errs)


def test_a_performer_lands_on_their_own_attempts(env):  # noqa: F811
    app, client, ids, _, settings = env
    mine = add_done(app, settings, ids, ids["perf"])
    theirs = add_done(app, settings, ids, ids["other"])
    sign_in(client, "p@a.org")
    assert client.get("/", follow_redirects=False).headers["location"] == "/analyses"
    page = client.get("/analyses")
    assert page.status_code == 200 and "My analyses" in page.text
    assert mine in page.text and theirs not in page.text
    # the headline of a result made before it was kept comes from the result, once
    headline = f"{_mean_error(fake_result()):.1f}°"
    assert headline in page.text
    assert client.get(f"/api/v1/analyses/{mine}").json()["mean_error_deg"] == _mean_error(
        fake_result()
    )
    # a coach is sent to the dashboard
    sign_in(client, "c@a.org")
    assert client.get("/analyses", follow_redirects=False).headers["location"] == "/dashboard"


def test_each_attempt_has_a_picture_of_its_video(env):  # noqa: F811
    app, client, ids, _, settings = env
    mine = add_done(app, settings, ids, ids["perf"])
    theirs = add_done(app, settings, ids, ids["other"])
    sign_in(client, "p@a.org")
    r = client.get(f"/api/v1/analyses/{mine}/thumbnail.jpg")
    assert r.status_code == 200 and r.headers["content-type"] == "image/jpeg"
    img = cv2.imdecode(np.frombuffer(r.content, np.uint8), cv2.IMREAD_COLOR)
    assert img is not None and img.shape[1] == 160 and img.std() > 1.0  # a picture, not blank
    assert client.get(f"/api/v1/analyses/{theirs}/thumbnail.jpg").status_code == 404
    # a video that cannot be decoded gives a plain 422, not a 500
    broken = add_done(app, settings, ids, ids["perf"])
    (settings.data_dir / "analyses" / broken / "video.mp4").write_bytes(b"not a video")
    r = client.get(f"/api/v1/analyses/{broken}/thumbnail.jpg")
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_video"


def test_the_headline_is_kept_when_the_result_arrives(env):  # noqa: F811
    app, client, ids, _, settings = env
    aid = add_done(app, settings, ids, ids["perf"])
    with app.state.sessionmaker() as s:  # as if the worker were still at it
        a = s.get(Analysis, aid)
        a.status, a.result_path = "running", None
        s.commit()
    doc = fake_result(n=5)
    (settings.data_dir / "analyses" / aid / "result.json").write_text(json.dumps(doc))
    sign_in(client, "c@a.org")
    a = client.get(f"/api/v1/analyses/{aid}").json()
    assert a["status"] == "done" and abs(a["mean_error_deg"] - _mean_error(doc)) < 1e-9


def test_a_coach_marks_analyses_reviewed(env):  # noqa: F811
    app, client, ids, _, settings = env
    first = add_done(app, settings, ids, ids["perf"])
    second = add_done(app, settings, ids, ids["perf"])
    sign_in(client, "p@a.org")
    assert client.put(f"/api/v1/analyses/{first}/reviewed").status_code == 403
    sign_in(client, "c@a.org")
    r = client.put(f"/api/v1/analyses/{first}/reviewed")
    assert r.status_code == 200 and r.json()["reviewed_at"] and r.json()["reviewed_by_id"]
    again = client.put(f"/api/v1/analyses/{first}/reviewed").json()
    assert again["reviewed_at"] == r.json()["reviewed_at"]  # the first mark stands

    def listed(**params) -> set[str]:
        return {a["id"] for a in client.get("/api/v1/analyses", params=params).json()["items"]}

    assert listed(reviewed="false") == {second} and listed(reviewed="true") == {first}
    to_review = client.get("/dashboard", params={"review": "to_review"}).text
    assert second in to_review and first not in to_review
    assert "to review" in to_review
    assert re.search(r"reviewed \d\d-\d\d", client.get("/dashboard").text)
    review = client.get(f"/analyses/{first}/review").text
    assert "Put back on the to-review list" in review
    cleared = client.delete(f"/api/v1/analyses/{first}/reviewed").json()
    assert cleared["reviewed_at"] is None and listed(reviewed="false") == {first, second}
    assert "Mark reviewed" in client.get(f"/analyses/{first}/review").text
    assert client.put("/api/v1/analyses/no-such-id/reviewed").status_code == 404
