"""The API's edges (issue 26 items 10 and 12): parameters bounded to what the database holds,
page sizes as documented, instants in one honest format, ``Authorization: Bearer``,
``Location`` on every 201, Idempotency-Key conflicts and plain validation errors."""

from __future__ import annotations

import uuid
from datetime import UTC, datetime
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from app import crud
from app.api.params import MAX_ID
from app.models import Analysis
from tests.app.conftest import ClubFixture, stored_files, upload

HUGE = [2**31, 2**63, 2**64, 10**40]
AID = str(uuid.uuid4())


@pytest.fixture
def raw_client(app):
    """A client that shows a server error as its 500 instead of raising it."""
    with TestClient(app, raise_server_exceptions=False) as c:
        yield c


# ---- ids


@pytest.mark.parametrize("n", HUGE)
@pytest.mark.parametrize(
    "method, path",
    [
        ("GET", "/api/v1/references/{n}"),
        ("GET", "/api/v1/references/{n}/thumbnail.svg"),
        ("GET", "/api/v1/references/{n}/preview.json"),
        ("PUT", "/api/v1/references/{n}/domain"),
        ("DELETE", "/api/v1/references/{n}"),
        ("GET", "/api/v1/performers/{n}"),
        ("GET", "/api/v1/performers/{n}/history"),
        ("GET", "/api/v1/performers/{n}/compare?a=" + AID + "&b=" + AID),
        ("GET", "/api/v1/keys/{n}"),
        ("DELETE", "/api/v1/keys/{n}"),
        ("GET", "/api/v1/analyses/" + AID + "/comments/{n}"),
        ("DELETE", "/api/v1/analyses/" + AID + "/comments/{n}"),
        ("GET", "/api/v1/analyses?performer_id={n}"),
        ("GET", "/api/v1/analyses?reference_id={n}"),
    ],
)
def test_ids_beyond_the_column_are_refused_not_500(raw_client, club, method, path, n):
    r = raw_client.request(method, path.format(n=n), headers=club.headers, json={})
    assert r.status_code == 422, (r.status_code, r.text)
    [problem] = r.json()["error"]["details"]["errors"]
    assert problem["loc"].split(".")[0] in ("path", "query")
    assert str(MAX_ID) in problem["message"]


@pytest.mark.parametrize(
    "path", ["/api/v1/references/{n}", "/api/v1/performers/{n}", "/api/v1/keys/{n}"]
)
def test_the_largest_id_is_looked_up(raw_client, club, path):
    r = raw_client.get(path.format(n=MAX_ID), headers=club.headers)
    assert r.status_code == 404 and r.json()["error"]["code"] == "not_found"


@pytest.mark.parametrize("field", ["reference_id", "performer_id"])
def test_upload_form_ids_are_bounded(raw_client, club, field):
    data = {"reference_id": 1, "performer_id": club.performer_id} | {field: 2**63}
    r = raw_client.post(
        "/api/v1/analyses", headers=club.headers, data=data,
        files={"video": ("v.mp4", b"not a video", "video/mp4")},
    )  # fmt: skip
    assert r.status_code == 422
    assert r.json()["error"]["details"]["errors"][0]["loc"] == f"body.{field}"


# ---- page size


def test_limit_is_documented_as_it_behaves(client, club, settings):
    params = client.get("/api/v1/openapi.json").json()["paths"]["/api/v1/analyses"]["get"]
    [limit] = [p for p in params["parameters"] if p["name"] == "limit"]
    assert "COACH_MAX_PAGE_SIZE" in limit["description"] and "100" in limit["description"]
    top = settings.max_page_size
    assert top == 100
    for path in ("/api/v1/analyses", "/api/v1/references", "/api/v1/performers"):
        assert client.get(f"{path}?limit={top}", headers=club.headers).status_code == 200
        r = client.get(f"{path}?limit={top + 1}", headers=club.headers)
        assert r.status_code == 422, path
        details = r.json()["error"]["details"]
        assert details["max_page_size"] == top
        assert details["errors"][0]["loc"] == "query.limit"
    assert client.get("/api/v1/analyses?limit=0", headers=club.headers).status_code == 422


@pytest.mark.settings(max_page_size=250)
def test_limit_follows_the_configured_page_size(client, club):
    r = client.get("/api/v1/analyses?limit=250", headers=club.headers)
    assert r.status_code == 200 and r.json()["limit"] == 250
    r = client.get("/api/v1/analyses?limit=251", headers=club.headers)
    assert r.status_code == 422 and r.json()["error"]["details"]["max_page_size"] == 250


# ---- created_before / created_after


def _analysis_at(app, club: ClubFixture, tmp_path: Path, when: datetime) -> str:
    with app.state.sessionmaker() as s:
        ref = crud.get_reference(s, club_id=club.id, reference_id=club.reference_id or 0)
        if ref is None:
            ref = crud.create_reference(s, club_id=club.id, name="r")
            club.reference_id = ref.id
        a = Analysis(
            club_id=club.id, performer_id=club.performer_id, reference_id=ref.id,
            video_path="", work_dir=str(tmp_path / "none"), status="done", created_at=when,
        )  # fmt: skip
        s.add(a)
        s.commit()
        return a.id


def test_created_before_is_an_iso_instant(client, app, club, tmp_path):
    early = _analysis_at(app, club, tmp_path, datetime(2024, 5, 1, 9, 30, tzinfo=UTC))
    late = _analysis_at(app, club, tmp_path, datetime(2024, 5, 1, 10, 30, tzinfo=UTC))

    def ids(query: str) -> set[str]:
        r = client.get(f"/api/v1/analyses?{query}", headers=club.headers)
        assert r.status_code == 200, r.text
        return {a["id"] for a in r.json()["items"]}

    assert ids("created_before=2024-05-01T10:00:00Z") == {early}
    assert ids("created_before=2024-05-01T12:00:00%2B02:00") == {early}  # 10:00 UTC
    assert ids("created_before=2024-05-01T10:00:00") == {early}  # no zone: UTC
    assert ids("created_after=2024-05-01T10:00:00Z") == {late}
    assert ids("created_before=2024-05-02") == {early, late}
    assert ids("created_after=2024-05-02") == set()


@pytest.mark.parametrize(
    "value", ["0.5", "1714550400", "1714550400000", "2024", "yesterday",
              "9999-12-31T23:59:59-05:00", "0001-01-01T00:00:00%2B01:00"],
)  # fmt: skip
def test_numbers_and_out_of_range_instants_are_refused(raw_client, club, value):
    for name in ("created_before", "created_after"):
        r = raw_client.get(f"/api/v1/analyses?{name}={value}", headers=club.headers)
        assert r.status_code == 422, (name, value, r.text)
        assert r.json()["error"]["details"]["errors"][0]["loc"] == f"query.{name}"


# ---- Authorization: Bearer


def test_bearer_is_an_api_key_too(client, club):
    bearer = {"Authorization": f"Bearer {club.key}"}
    assert client.get("/api/v1/references", headers=bearer).status_code == 200
    r = client.post("/api/v1/keys", headers=bearer, json={"name": "ci"})
    assert r.status_code == 201
    both = bearer | {"X-API-Key": club.key}
    assert client.get("/api/v1/references", headers=both).status_code == 200


def test_a_wrong_bearer_is_401(client, club):
    for headers in (
        {"Authorization": "Bearer mc_nope"},
        {"Authorization": f"Bearer {club.key}x"},
        {"Authorization": f"Bearer {club.key}", "X-API-Key": "mc_other"},  # they disagree
    ):
        r = client.get("/api/v1/references", headers=headers)
        assert r.status_code == 401, headers
        assert r.json()["error"]["code"] == "unauthorized"
        assert r.headers["WWW-Authenticate"]
    basic = {"Authorization": "Basic eDp5"}  # not a bearer: no key, no session
    assert client.get("/api/v1/references", headers=basic).status_code == 401


def test_a_revoked_key_is_401_as_a_bearer(client, club):
    new = client.post("/api/v1/keys", headers=club.headers, json={}).json()
    assert client.delete(f"/api/v1/keys/{new['id']}", headers=club.headers).status_code == 204
    r = client.get("/api/v1/references", headers={"Authorization": f"Bearer {new['key']}"})
    assert r.status_code == 401


# ---- Location on 201


def _created(client, r, headers) -> dict:
    assert r.status_code == 201, r.text
    where = r.headers["Location"]
    assert where.startswith("/")
    got = client.get(where, headers=headers)
    assert got.status_code == 200, (where, got.text)
    return got.json() if "json" in got.headers["content-type"] else {}


def test_every_201_has_a_location(client, app, club_ref, video_file, bvh_file):
    h = club_ref.headers
    key = client.post("/api/v1/keys", headers=h, json={"name": "k"})
    assert _created(client, key, h)["id"] == key.json()["id"]
    performer = client.post(
        "/api/v1/performers", headers=h, json={"email": "new@alpha.org", "display_name": "N"}
    )
    assert _created(client, performer, h)["id"] == performer.json()["id"]
    with open(bvh_file, "rb") as f:
        ref = client.post("/api/v1/references", headers=h,
                          files={"file": ("r.bvh", f, "application/octet-stream")})  # fmt: skip
    assert _created(client, ref, h)["id"] == ref.json()["id"]
    analysis = upload(client, club_ref, video_file)
    assert _created(client, analysis, h)["id"] == analysis.json()["id"]
    invite = client.post("/api/v1/invites", headers=h, json={"display_name": "Kim"})
    assert invite.headers["Location"] == invite.json()["path"]
    _created(client, invite, h)  # the join page

    with app.state.sessionmaker() as s:  # comments are written by people
        crud.create_user(s, club_id=club_ref.id, role="coach", email="c@alpha.org",
                         display_name="C", password="a long password")  # fmt: skip
    r = client.post("/api/v1/session", json={"email": "c@alpha.org", "password": "a long password"})
    assert r.status_code == 200
    aid = analysis.json()["id"]
    comment = client.post(f"/api/v1/analyses/{aid}/comments", json={"body": "knees", "frame": 3})
    assert _created(client, comment, {})["body"] == "knees"


# ---- Idempotency-Key


def test_an_idempotency_key_reused_for_another_upload_is_409(
    client, club_ref, video_file, queue, settings, tmp_path
):
    first = upload(client, club_ref, video_file, key="swing-42")
    assert first.status_code == 201
    again = upload(client, club_ref, video_file, key="swing-42")
    assert again.status_code == 200 and again.json()["id"] == first.json()["id"]
    files = stored_files(settings)

    other = client.post(
        "/api/v1/performers", headers=club_ref.headers,
        json={"email": "second@alpha.org", "display_name": "Second"},
    ).json()  # fmt: skip
    r = upload(client, club_ref, video_file, key="swing-42", performer_id=other["id"])
    assert r.status_code == 409, r.text
    error = r.json()["error"]
    assert error["code"] == "idempotency_conflict"
    assert error["details"]["analysis_id"] == first.json()["id"]

    changed = tmp_path / "changed.mp4"
    changed.write_bytes(video_file.read_bytes() + b"\0")
    assert upload(client, club_ref, changed, key="swing-42").status_code == 409
    assert len(queue.jobs) == 1 and stored_files(settings) == files
    assert upload(client, club_ref, changed, key="swing-43").status_code == 201


# ---- plain validation errors


def test_validation_errors_name_fields_plainly(client, club):
    r = client.patch("/api/v1/club", headers=club.headers, json={"webhook_url": "ftp://x"})
    assert r.status_code == 422
    error = r.json()["error"]
    plain = 'must be an http or https URL, or "" to remove the webhook'
    assert error["message"] == f"webhook_url: {plain}"
    assert error["details"]["errors"] == [
        {"loc": "body.webhook_url", "message": plain, "type": "value_error"}
    ]
    r = client.post("/api/v1/keys", headers=club.headers | {"Content-Type": "application/json"},
                    content=b"{bad")  # fmt: skip
    [problem] = r.json()["error"]["details"]["errors"]
    assert problem["loc"] == "body" and "not valid JSON" in problem["message"]
    r = client.post("/api/v1/performers", headers=club.headers, json={"email": "x"})
    locs = [p["loc"] for p in r.json()["error"]["details"]["errors"]]
    assert locs == ["body.email", "body.display_name"]


def test_no_pydantic_or_errno_internals_reach_a_client(raw_client, club_ref, tmp_path):
    junk = tmp_path / "junk.mp4"
    junk.write_bytes(b"\0\1\2 not a video at all" * 100)
    r = upload(raw_client, club_ref, junk)
    assert r.status_code == 422
    for body in (
        r.text,
        raw_client.patch("/api/v1/club", headers=club_ref.headers, json={"webhook_url": 5}).text,
        raw_client.get("/api/v1/analyses?limit=x&status=nope", headers=club_ref.headers).text,
    ):
        for internal in ("function-wrap", "literal[", "Value error,", "[Errno", "wrap_val"):
            assert internal not in body, (internal, body)
