"""The browser pages and their JSON endpoints through FastAPI's TestClient (no browser)."""

from __future__ import annotations

import csv
import io
import json
import re
import shutil
import uuid
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from app import crud
from app.core import media
from app.core.config import Settings
from app.core.queue import get_queue
from app.main import create_app
from app.models import Analysis
from engine.body.skeleton import BONE_NAMES, JOINTS
from engine.report import ONE_CAMERA_NOTE
from tests.app.conftest import SAMPLE_BVH, SAMPLE_VIDEO, RecordingQueue

PASSWORD = "correct horse battery"


def fake_result(n: int = 8, width: int = 320, height: int = 240) -> dict:
    """A small result document: a standing figure, errors growing with t'."""
    rng = __import__("numpy").random.default_rng(0)
    base = rng.normal(size=(17, 3)) * 0.3
    frames = []
    for t in range(n):
        j3 = (base + 0.01 * t).tolist()
        j2 = [[160 + 40 * x, 120 - 40 * y] for x, y, _ in j3]
        errs = [min(5.0 + 10.0 * t + b, 90.0) for b in range(16)]
        frames.append({
            "t": t, "reference_frame": 10 + 2 * t, "joints_3d": j3, "joints_2d": j2,
            "candidates": [j3], "selected": 0, "posture_error_deg": sum(errs) / 16,
            "bone_errors_deg": errs, "flags": [],
        })  # fmt: skip
    return {
        "version": 1,
        "reference": {"name": "ref", "frames": 100, "fps": 120.0},
        "video": {"frames": n, "fps": 10.0, "width": width, "height": height},
        "joints": list(JOINTS),
        "camera": {"scale": 1.0, "theta_z_deg": 0.0, "cx": 160.0, "cy": 120.0},
        "frames": frames,
        "segments": [
            {
                "reference_start": 10,
                "reference_end": 16,
                "performer_start": 0,
                "performer_end": 3,
                "mean_error_deg": 20.0,
                "bone_mean_errors_deg": [20.0] * 16,
            },
            {
                "reference_start": 16,
                "reference_end": 24,
                "performer_start": 3,
                "performer_end": n - 1,
                "mean_error_deg": 60.0,
                "bone_mean_errors_deg": [float(b) for b in range(16)],
            },
        ],  # fmt: skip
        "timing_s": {"total": 1.0},
    }


@pytest.fixture
def env(tmp_path: Path):
    if not SAMPLE_BVH.exists() or not SAMPLE_VIDEO.exists():
        pytest.skip("../shared data is not beside the clone")
    settings = Settings(data_dir=tmp_path / "data", reflect_interval_s=0, sse_poll_s=0.05,
                        rate_limit_per_s=1000, rate_limit_burst=1000)  # fmt: skip
    app = create_app(settings)
    queue = RecordingQueue()
    app.dependency_overrides[get_queue] = lambda: queue
    with app.state.sessionmaker() as s:
        club = crud.create_club(s, name="alpha")
        s.commit()
        coach = crud.create_user(s, club_id=club.id, role="coach", email="c@a.org",
                                 display_name="Coach", password=PASSWORD)  # fmt: skip
        perf = crud.create_user(s, club_id=club.id, role="performer", email="p@a.org",
                                display_name="Pat", password=PASSWORD)  # fmt: skip
        other = crud.create_user(s, club_id=club.id, role="performer", email="o@a.org",
                                 display_name="Olive", password=PASSWORD)  # fmt: skip
        ref = crud.create_reference(s, club_id=club.id, name="swing")
        dest = settings.data_dir / "references" / str(ref.id) / "reference.bvh"
        dest.parent.mkdir(parents=True)
        shutil.copyfile(SAMPLE_BVH, dest)
        ref.bvh_path = str(dest)
        ref.derived = {"frames": 100, "fps": 120.0, "segments": [10, 50, 90],
                       "first_motion_frame": 1, "duration_s": 1.0}  # fmt: skip
        s.commit()
        ids = {"club": club.id, "coach": coach.id, "perf": perf.id, "other": other.id,
               "ref": ref.id}  # fmt: skip
    with TestClient(app) as client:
        yield app, client, ids, queue, settings


def sign_in(client, email: str) -> None:
    r = client.post("/api/v1/session", json={"email": email, "password": PASSWORD})
    assert r.status_code == 200, r.text


def add_done(app, settings, ids, performer_id: int) -> str:
    aid = str(uuid.uuid4())
    work = settings.data_dir / "analyses" / aid
    work.mkdir(parents=True)
    shutil.copyfile(SAMPLE_VIDEO, work / "video.mp4")
    (work / "result.json").write_text(json.dumps(fake_result()))
    (work / "status.json").write_text(json.dumps({"state": "done", "stage": "done",
                                                  "progress": 1.0, "message": "", "error": None}))  # fmt: skip  # noqa: E501
    with app.state.sessionmaker() as s:
        s.add(Analysis(id=aid, club_id=ids["club"], performer_id=performer_id,
                       reference_id=ids["ref"], video_path=str(work / "video.mp4"),
                       work_dir=str(work), status="done", progress=1.0,
                       result_path=str(work / "result.json")))  # fmt: skip
        s.commit()
    return aid


def test_pages_redirect_to_sign_in_and_by_role(env):
    _, client, *_ = env
    r = client.get("/dashboard", follow_redirects=False)
    assert r.status_code == 303 and r.headers["location"].startswith("/login?next=")
    assert "Sign in" in client.get("/login").text
    sign_in(client, "p@a.org")
    assert client.get("/", follow_redirects=False).headers["location"] == "/analyses"
    assert client.get("/references").status_code == 403
    sign_in(client, "c@a.org")
    assert client.get("/", follow_redirects=False).headers["location"] == "/dashboard"


def test_every_page_renders_for_a_coach(env):
    app, client, ids, _, settings = env
    aid = add_done(app, settings, ids, ids["perf"])
    sign_in(client, "c@a.org")
    for path in ("/upload", "/dashboard", "/references", f"/analyses/{aid}",
                 f"/analyses/{aid}/review", f"/analyses/{aid}/report",
                 f"/dashboard?performer={ids['perf']}&status=done&since=2000-01-01"):  # fmt: skip
        r = client.get(path)
        assert r.status_code == 200, (path, r.text[:300])
        page = re.sub(r"data:image/[a-z]+;base64,[A-Za-z0-9+/=]+", "", r.text)  # inline stills
        assert "cdn" not in page.lower() and "googleapis" not in page

    def rows(url: str) -> str:
        return client.get(url).text.split("<tbody>")[1]

    assert "<td>Pat</td>" in rows("/dashboard")
    assert "<td>Pat</td>" not in rows(f"/dashboard?performer={ids['other']}")
    assert "<svg" in client.get(f"/analyses/{aid}/report").text
    # the limits of one camera are said beside every result
    for path in (f"/analyses/{aid}", f"/analyses/{aid}/review", f"/analyses/{aid}/report"):
        assert ONE_CAMERA_NOTE in client.get(path).text, path


def test_upload_from_the_page_queues_for_the_signed_in_performer(env):
    _, client, ids, queue, _ = env
    sign_in(client, "p@a.org")
    with open(SAMPLE_VIDEO, "rb") as f:
        r = client.post("/api/v1/analyses", data={"reference_id": ids["ref"]},
                        files={"video": ("clip.mp4", f, "video/mp4")})  # fmt: skip
    assert r.status_code == 201, r.text
    assert len(queue.jobs) == 1
    status = client.get(f"/api/v1/analyses/{r.json()['id']}").json()
    assert status["performer_id"] == ids["perf"] and status["status"] == "queued"
    assert "Analysing your video" in client.get(f"/analyses/{r.json()['id']}").text


def test_performers_see_only_their_own_analyses(env):
    app, client, ids, _, settings = env
    mine = add_done(app, settings, ids, ids["perf"])
    theirs = add_done(app, settings, ids, ids["other"])
    sign_in(client, "p@a.org")
    assert client.get(f"/api/v1/analyses/{mine}/result").status_code == 200
    assert client.get(f"/api/v1/analyses/{theirs}/result").status_code == 404
    assert client.get(f"/analyses/{theirs}").status_code == 404


def test_results_summary_video_and_exports(env):
    app, client, ids, _, settings = env
    aid = add_done(app, settings, ids, ids["perf"])
    sign_in(client, "p@a.org")
    summary = client.get(f"/api/v1/analyses/{aid}/summary").json()
    assert [s["name"] for s in summary["segments"]] == ["segment 1", "segment 2"]
    # in a coach's words: the bone's label, the tempo as one sentence
    assert summary["segments"][1]["worst_bones"][0][0] == "head"
    assert summary["bone_labels"][9] == "left upper arm" and BONE_NAMES[9] == "l_shoulder->l_elbow"
    keys = summary["key_positions"]  # between the segments, named by them
    assert [k["name"] for k in keys] == ["start of segment 1", "start of segment 2",
                                         "end of segment 2"]  # fmt: skip
    assert keys[1]["frame"] == summary["segments"][1]["performer_start"]
    assert all("->" not in b for s in summary["segments"] for b in s["misfit_bones"])
    assert summary["segments"][0]["tempo_text"].endswith("than the expert") or summary[
        "segments"][0]["tempo_text"] == "the expert's tempo"  # fmt: skip
    r = client.get(f"/api/v1/analyses/{aid}/video.mp4")
    assert r.status_code == 200 and r.headers["content-type"] == "video/mp4"
    import av

    with av.open(io.BytesIO(r.content)) as c:
        assert c.streams.video[0].codec_context.name == "h264"
    rows = list(csv.reader(io.StringIO(client.get(f"/api/v1/analyses/{aid}/export.csv").text)))
    assert rows[0][:5] == ["t", "time_s", "reference_frame", "selected", "posture_error_deg"]
    assert len(rows) == 1 + 8 and len(rows[1]) == len(rows[0])
    assert len(set(rows[0])) == len(rows[0])  # every column named once
    assert float(rows[2][rows[0].index("error_deg_left_pelvis")]) == pytest.approx(15.0)
    assert {"range_deg_left_upper_arm", "angle_deg_right_knee", "angle_deg_upper_back"} <= set(
        rows[0])  # fmt: skip
    bvh = client.get(f"/api/v1/analyses/{aid}/export.bvh")
    assert bvh.status_code == 200 and bvh.text.startswith("HIERARCHY")
    assert "attachment" in bvh.headers["content-disposition"]


def test_comments_pinned_and_persisted(env):
    app, client, ids, _, settings = env
    aid = add_done(app, settings, ids, ids["perf"])
    sign_in(client, "c@a.org")
    base = f"/api/v1/analyses/{aid}/comments"
    assert client.post(base, json={"body": "elbow!", "frame": 3}).status_code == 201
    assert client.post(base, json={"body": "slow top", "segment": 1}).status_code == 201
    assert client.post(base, json={"body": ""}).status_code == 422
    items = client.get(base).json()["items"]
    assert [(c["body"], c["frame"], c["segment"]) for c in items] == [
        ("elbow!", 3, None), ("slow top", None, 1)]  # fmt: skip
    sign_in(client, "p@a.org")  # the performer reads the coach's comments but cannot delete them
    assert client.get(base).json()["total"] == 2
    assert client.delete(f"{base}/{items[0]['id']}").status_code == 403
    sign_in(client, "c@a.org")
    assert client.delete(f"{base}/{items[0]['id']}").status_code == 204
    assert client.get(base).json()["total"] == 1


def test_a_drawing_is_saved_with_its_comment_on_a_frame(env):
    app, client, ids, _, settings = env
    aid = add_done(app, settings, ids, ids["perf"])
    sign_in(client, "c@a.org")
    base = f"/api/v1/analyses/{aid}/comments"
    line = [[0.2, 0.3], [0.25, 0.35], [0.3, 0.5]]
    r = client.post(base, json={"body": "keep the elbow here", "frame": 4, "drawing": [line]})
    assert r.status_code == 201, r.text
    assert r.json()["drawing"] == [line]
    got = client.get(base).json()["items"][0]
    assert (got["frame"], got["drawing"]) == (4, [line])
    assert client.post(base, json={"body": "x", "frame": 4}).json()["drawing"] is None
    for bad in (
        {"body": "no frame", "drawing": [line]},  # a drawing belongs to a frame
        {"body": "off the picture", "frame": 1, "drawing": [[[0.2, 0.3], [1.4, 0.3]]]},
        {"body": "a dot", "frame": 1, "drawing": [[[0.2, 0.3]]]},
        {"body": "nothing", "frame": 1, "drawing": []},
    ):
        assert client.post(base, json=bad).status_code == 422, bad


def test_key_positions_take_the_coachs_names(env):
    app, client, ids, _, settings = env
    aid = add_done(app, settings, ids, ids["perf"])
    sign_in(client, "c@a.org")
    url = f"/api/v1/references/{ids['ref']}/domain"
    bad = client.put(url, json={"key_position_names": ["address", "top"]})
    assert bad.status_code == 422 and "2 segments have 3 key positions" in bad.text
    r = client.put(url, json={"key_position_names": ["address", "top", "finish"]})
    assert r.status_code == 200, r.text
    keys = client.get(f"/api/v1/analyses/{aid}/summary").json()["key_positions"]
    assert [k["name"] for k in keys] == ["address", "top", "finish"]
    client.put(url, json={"key_position_names": []})  # back to the segments' own words
    keys = client.get(f"/api/v1/analyses/{aid}/summary").json()["key_positions"]
    assert keys[1]["name"] == "start of segment 2"


def test_reference_thumbnail_and_domain_edit(env):
    _, client, ids, _, settings = env
    sign_in(client, "c@a.org")
    refs = client.get("/api/v1/references").json()["items"]
    assert refs[0]["segment_names"] == ["segment 1", "segment 2"]
    svg = client.get(refs[0]["thumbnail"])
    assert svg.status_code == 200 and svg.text.startswith("<svg") and svg.text.count("<line") == 16
    r = client.put(f"/api/v1/references/{ids['ref']}/domain", json={
        "segment_names": ["backswing", "downswing"], "bone_weights": {"l_elbow": 2},
        "tolerances_deg": {"l_knee": 15}})  # fmt: skip
    assert r.status_code == 200, r.text
    assert r.json()["segment_names"] == ["backswing", "downswing"]
    # stored once, with the reference (every analysis request carries it); no file beside it
    stored = client.get(f"/api/v1/references/{ids['ref']}").json()["domain"]
    assert stored["bone_weights"] == {"l_elbow": 2}
    assert list((settings.data_dir / "references" / str(ids["ref"])).glob("*.json")) == []
    bad = client.put(f"/api/v1/references/{ids['ref']}/domain",
                     json={"bone_weights": {"tail": 1}})  # fmt: skip
    assert bad.status_code == 422
    three = client.put(f"/api/v1/references/{ids['ref']}/domain",
                       json={"segment_names": ["a", "b", "c"]})  # fmt: skip
    assert three.status_code == 422 and "2 segments, got 3" in three.text
    sign_in(client, "p@a.org")
    assert client.put(f"/api/v1/references/{ids['ref']}/domain", json={}).status_code == 403


def test_joint_angles_of_a_right_angle():
    import numpy as np

    j = np.zeros((1, 17, 3))
    j[0, JOINTS.index("l_hip")] = [0, 0, 0]
    j[0, JOINTS.index("l_knee")] = [0, -1, 0]
    j[0, JOINTS.index("l_ankle")] = [1, -1, 0]
    names = [a[0] for a in media.JOINT_ANGLES]
    k = next(i for i, n in enumerate(names) if n == "angle_deg_left_knee")
    assert media.joint_angles_deg(j)[0, k] == pytest.approx(90.0)


def test_printable_plot_shades_the_frames_the_video_does_not_confirm():
    result = fake_result()
    assert "misfit-mark" not in media.error_plot_svg(result)
    for t in (2, 3):
        result["frames"][t]["flags"] = ["image_misfit"]
    assert media.error_plot_svg(result).count('class="misfit-mark"') == 2


def test_printable_plot_axis_fits_the_errors():
    """Small errors get a small axis (which frames stand out stays visible), large ones fit."""
    assert [media.plot_top(m) for m in (0.0, 1.5, 3.7, 7.0, 15.0, 90.0, 500.0)] == [
        4, 4, 8, 8, 20, 120, 180,
    ]  # fmt: skip
    result = fake_result()
    for f in result["frames"]:
        f["posture_error_deg"] = 1.0
    svg = media.error_plot_svg(result)
    assert ">4&#176;<" in svg and ">20&#176;<" not in svg
    result["frames"][0]["posture_error_deg"] = 30.0
    assert ">40&#176;<" in media.error_plot_svg(result)


def test_report_stills_show_a_segment_where_the_video_disagrees():
    result = fake_result()  # errors grow with t: segment 1's worst frame is its last
    first = media.still_frames(result, n=2)
    result["frames"][1]["flags"] = ["image_misfit"]
    assert 1 not in first and 1 in media.still_frames(result, n=2)


@pytest.mark.parametrize(
    ("ratio", "words"),
    [(1.0, "the expert's tempo"), (1.004, "the expert's tempo"),
     (1.12, "12 % slower than the expert"), (0.97, "3 % faster than the expert"),
     (None, "tempo unknown"), (0.0, "tempo unknown"), (float("nan"), "tempo unknown")],
)  # fmt: skip
def test_tempo_is_said_one_way(ratio, words):
    from engine.report import tempo_words

    assert tempo_words(ratio) == words


def test_every_bone_and_bend_has_a_coach_word():
    from engine.body.skeleton import BEND_LABELS, BONE_LABELS, BONE_PARENT, bone_label

    assert len(set(BONE_LABELS)) == len(BONE_LABELS) == len(BONE_NAMES)
    # a bend for every bone that has a bone before it, none for those leaving the root
    assert [b is None for b in BEND_LABELS] == [int(p) == 0 for p in BONE_PARENT]
    assert bone_label("l_elbow") == "left upper arm" == bone_label("l_shoulder->l_elbow")
    assert bone_label("tail") == "tail"


def test_each_joints_bend_the_performers_and_the_experts(env):
    """/angles: 13 bends per frame, the performer's from the result's 3D posture, the
    expert's from the reference at the matched frame C(t')."""
    import numpy as np

    from app.models import Reference
    from engine.body.posture_angles import posture_angles_deg

    app, client, ids, _, settings = env
    aid = add_done(app, settings, ids, ids["perf"])
    theirs = add_done(app, settings, ids, ids["other"])
    sign_in(client, "p@a.org")
    r = client.get(f"/api/v1/analyses/{aid}/angles")
    assert r.status_code == 200, r.text
    d = r.json()
    assert [b["label"] for b in d["bends"]][:2] == ["left hip", "left knee"]
    assert d["bends"][1]["joint"] == JOINTS.index("l_knee")
    doc = fake_result()
    want = media.joint_angles_deg(np.array([f["joints_3d"] for f in doc["frames"]]))
    np.testing.assert_allclose(d["performer"], want, atol=0.06)
    with app.state.sessionmaker() as s:
        bvh = s.get(Reference, ids["ref"]).bvh_path
    ref = media.reference_joints(bvh)
    idx = [min(f["reference_frame"], len(ref) - 1) for f in doc["frames"]]
    np.testing.assert_allclose(d["expert"], media.joint_angles_deg(ref[idx]), atol=0.06)
    # the spine's tilt and the shoulders' and hips' turn, each body against its first frame
    assert [p["label"] for p in d["posture"]] == [
        "spine forward tilt", "spine side tilt", "shoulder turn", "hip turn"]
    perf = np.array([f["joints_3d"] for f in doc["frames"]])
    np.testing.assert_allclose(d["performer_posture"], posture_angles_deg(perf), atol=0.06)
    np.testing.assert_allclose(d["expert_posture"], posture_angles_deg(ref[idx]), atol=0.06)
    assert np.allclose(d["performer_posture"][0][2:], 0.0)  # no turn at the first frame
    assert client.get(f"/api/v1/analyses/{theirs}/angles").status_code == 404
