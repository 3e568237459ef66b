import pytest

from tests.app.conftest import data_files, make_club, stored_files


def _upload(client, club, bvh_file, domain: bytes | None = None):
    """POST a reference, with a domain JSON when given."""
    with open(bvh_file, "rb") as f:
        files = {"file": ("a.bvh", f)} | ({"domain": ("d.json", domain)} if domain else {})
        return client.post("/api/v1/references", headers=club.headers, files=files)


def test_reference_upload_list_get_delete(client, club_ref, settings):
    h = club_ref.headers
    listed = client.get("/api/v1/references", headers=h).json()["items"]
    assert [r["name"] for r in listed] == ["swing"]
    ref = client.get(f"/api/v1/references/{club_ref.reference_id}", headers=h).json()
    assert ref["derived"]["frames"] == 580 and ref["derived"]["fps"] > 100
    assert "bvh_path" not in ref
    stored = data_files(settings, "references")
    assert any(p.name == "reference.bvh" for p in stored)
    assert (
        client.delete(f"/api/v1/references/{club_ref.reference_id}", headers=h).status_code == 204
    )
    assert client.get(f"/api/v1/references/{club_ref.reference_id}", headers=h).status_code == 404
    assert not any(p.is_file() for p in data_files(settings, "references"))


def test_unmappable_bvh_is_422_naming_missing_joints(client, club, bvh_file, tmp_path, settings):
    bad = tmp_path / "bad.bvh"
    bad.write_text(bvh_file.read_text().replace("LeftForeArm", "Tentacle"))
    with open(bad, "rb") as f:
        r = client.post("/api/v1/references", headers=club.headers, files={"file": ("b.bvh", f)})
    assert r.status_code == 422
    assert r.json()["error"]["code"] == "invalid_reference"
    assert "l_elbow" in r.json()["error"]["message"]
    assert client.get("/api/v1/references", headers=club.headers).json()["items"] == []
    assert stored_files(settings) == []


def test_domain_json_is_checked_and_kept(client, club, bvh_file):
    r = _upload(client, club, bvh_file, b'{"segments": [1, 200, 400]}')
    assert r.status_code == 201, r.text
    derived = r.json()["derived"]
    # the coach's starts, then the last frame: every analysis of it uses these three segments
    assert derived["segments"] == [1, 200, 400, derived["frames"] - 1]
    r = _upload(client, club, bvh_file, b"[1, 2")
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_domain"


@pytest.mark.parametrize(
    ("doc", "says"),
    [
        (b'{"segments": [1, 200, 100000]}', "segments"),  # beyond the motion's last frame
        (b'{"segments": [200, 1]}', "increasing"),
        (b'{"segments": [1, 200], "segment_names": ["a", "b", "c"]}', "2 segments"),
        (b'{"segment_names": ["a", "b", "c", "d", "e", "f", "g", "h"]}', "detected"),
    ],
)
def test_domain_segments_that_do_not_fit_the_motion_are_refused(client, club, bvh_file, doc, says):
    r = _upload(client, club, bvh_file, doc)
    assert r.status_code == 422, r.text
    assert r.json()["error"]["code"] == "invalid_domain"
    assert says in r.json()["error"]["message"]


def test_detected_segments_are_stored_when_the_domain_gives_none(client, club, bvh_file):
    from engine.io.bvh import load_reference
    from engine.reference.boundaries import reference_boundaries

    r = _upload(client, club, bvh_file)
    assert r.status_code == 201, r.text
    seg = reference_boundaries(load_reference(bvh_file).motion)
    assert r.json()["derived"]["segments"] == [*seg.starts, seg.end]


def test_a_coach_moves_adds_and_resets_segment_boundaries(client, club, bvh_file):
    from engine.io.bvh import load_reference
    from engine.reference.boundaries import reference_boundaries

    ref = _upload(client, club, bvh_file).json()
    url, h = f"/api/v1/references/{ref['id']}", club.headers
    curve = client.get(url + "/motion.json", headers=h).json()
    assert curve["frames"] == ref["derived"]["frames"] == 580 and curve["step"] == 1
    speed = curve["speed_m_per_frame"]
    assert len(speed) == 580 and max(speed) > 0
    # frames up to the motion's first (after a conversion T-pose) are not motion
    assert curve["first_motion_frame"] == 1 and speed[:2] == [0.0, 0.0]
    assert curve["segments"] == ref["derived"]["segments"]
    r = client.put(
        url + "/domain",
        headers=h,
        json={"segments": [1, 150, 300], "segment_names": ["a", "b", "c"]},
    )
    assert r.status_code == 200, r.text
    got = r.json()
    assert got["derived"]["segments"] == [1, 150, 300, 579]
    assert got["domain"]["segments"] == [1, 150, 300] and got["segment_names"] == ["a", "b", "c"]
    assert client.get(url + "/motion.json", headers=h).json()["segments"] == [1, 150, 300, 579]
    # names that no longer match, or a start beyond the motion, are refused and change nothing
    bad = client.put(
        url + "/domain", headers=h, json={"segments": [1, 300], "segment_names": ["a", "b", "c"]}
    )
    assert bad.status_code == 422 and "2 segments" in bad.json()["error"]["message"]
    beyond = client.put(url + "/domain", headers=h, json={"segments": [1, 9000]})
    assert beyond.status_code == 422 and beyond.json()["error"]["code"] == "invalid_domain"
    assert client.get(url, headers=h).json()["derived"]["segments"] == [1, 150, 300, 579]
    # [] goes back to the boundaries found in the motion
    back = client.put(url + "/domain", headers=h, json={"segments": []}).json()
    seg = reference_boundaries(load_reference(bvh_file).motion)
    assert (
        back["derived"]["segments"] == [*seg.starts, seg.end] and "segments" not in back["domain"]
    )


def test_other_clubs_reference_is_404(client, app, club_ref):
    other = make_club(app, "beta")
    url = f"/api/v1/references/{club_ref.reference_id}"
    assert client.get(url, headers=other.headers).status_code == 404
    assert client.delete(url, headers=other.headers).status_code == 404
    assert client.get(url + "/motion.json", headers=other.headers).status_code == 404
    moved = client.put(url + "/domain", headers=other.headers, json={"segments": [1, 9]})
    assert moved.status_code == 404
    assert client.get("/api/v1/references", headers=other.headers).json()["items"] == []


def test_performers(client, club):
    body = {"email": "Ann@Example.org", "display_name": "Ann"}
    r = client.post("/api/v1/performers", headers=club.headers, json=body)
    assert r.status_code == 201 and r.json()["role"] == "performer"
    assert client.post("/api/v1/performers", headers=club.headers, json=body).status_code == 409
    listed = client.get("/api/v1/performers", headers=club.headers).json()["items"]
    names = [p["display_name"] for p in listed]
    assert names == ["Performer", "Ann"]


def test_domain_in_the_engine_format_is_validated(client, club, bvh_file):
    doc = b'{"sport": "golf", "tolerances_deg": {"l_knee": 15}, "segments": [1, 300]}'
    r = _upload(client, club, bvh_file, doc)
    assert r.status_code == 201, r.text
    r = _upload(client, club, bvh_file, b'{"tolerances_deg": {"toe": 3}}')
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_domain"
