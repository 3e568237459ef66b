"""POST /api/v1/references/takes: a reference built from several takes of one action."""

import pytest

from tests.app.conftest import stored_files
from tests.conftest import CMU


def _takes(*names: str):
    for n in names:
        if not (CMU / f"{n}.bvh").exists():
            pytest.skip("../shared/data/cmu is not beside the clone")
    return [("takes", (f"{n}.bvh", (CMU / f"{n}.bvh").read_bytes())) for n in names]


def test_takes_build_a_reference_with_the_experts_variation(client, club):
    r = client.post("/api/v1/references/takes", headers=club.headers,
                    files=_takes("64_29", "64_30"), data={"sport": "fitness"})  # fmt: skip
    assert r.status_code == 201, r.text
    ref = r.json()
    takes = ref["derived"]["takes"]
    assert takes["kept"] == ["64_29", "64_30"] and takes["median_take"] in takes["kept"]
    assert len(takes["bone_sd_deg_mean"]) == 16
    # the spread is stored for the analyses but summarised in what the API returns
    variation = ref["domain_config"]["variation"]
    assert "bone_sd_deg" not in variation and variation["frames"] == ref["frames"]
    assert ref["domain"]["sport"] == "fitness"
    png = client.get(ref["takes_plot"], headers=club.headers)
    assert png.status_code == 200 and png.content[:4] == b"\x89PNG"
    assert client.get(ref["strip"], headers=club.headers).status_code == 200
    # the stored domain carries the spread every analysis request will pass to the engine
    from app.models import Reference

    with client.app.state.sessionmaker() as session:
        stored = session.get(Reference, ref["id"]).domain_config
    assert len(stored["variation"]["bone_sd_deg"]) == ref["frames"]


def test_a_take_of_another_action_is_left_out_and_named(client, club):
    r = client.post("/api/v1/references/takes", headers=club.headers,
                    files=_takes("63_01", "63_02", "64_17"))  # fmt: skip
    assert r.status_code == 201, r.text
    takes = r.json()["derived"]["takes"]
    assert takes["kept"] == ["63_01", "63_02"]
    assert "64_17" in takes["warnings"][0]


def test_bad_takes_are_refused_and_nothing_is_kept(client, club, settings, tmp_path):
    h = club.headers
    r = client.post("/api/v1/references/takes", headers=h, files=_takes("64_29"))
    assert r.status_code == 422 and "2 to 12 takes" in r.json()["error"]["message"]
    r = client.post("/api/v1/references/takes", headers=h, files=_takes("63_01", "64_17"))
    assert r.status_code == 422 and "fewer than two takes of one action" in r.text
    files = _takes("64_29") + [("takes", ("junk.bvh", b"not a bvh"))]
    r = client.post("/api/v1/references/takes", headers=h, files=files)
    assert r.status_code == 422 and "take junk:" in r.json()["error"]["message"]
    assert client.get("/api/v1/references", headers=h).json()["items"] == []
    assert stored_files(settings) == []


def test_a_reference_from_one_bvh_has_no_takes_plot(client, club_ref):
    h = club_ref.headers
    ref = client.get(f"/api/v1/references/{club_ref.reference_id}", headers=h).json()
    assert ref["takes_plot"] == ""
    r = client.get(f"/api/v1/references/{club_ref.reference_id}/takes.png", headers=h)
    assert r.status_code == 404


@pytest.mark.parametrize("method", ["GET", "DELETE"])
def test_other_methods_on_the_takes_path_are_405_not_a_bad_id(client, club, method):
    r = client.request(method, "/api/v1/references/takes", headers=club.headers)
    assert r.status_code == 405 and r.headers["Allow"] == "POST", r.text
    assert client.get("/api/v1/references/999", headers=club.headers).status_code == 404
