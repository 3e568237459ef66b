import json
import os
import threading
import time
from datetime import UTC, datetime, timedelta
from http.server import BaseHTTPRequestHandler, HTTPServer
from pathlib import Path

import pytest

from app.core.security import verify_webhook
from app.models import Analysis
from engine.body.skeleton import JOINTS
from tests.app.conftest import make_club, stored_files, upload


def _frame(t: int) -> dict:
    """A complete result frame (engine.io.result_reader checks every key)."""
    j2 = [[160.0 + 10 * j, 100.0 + 5 * j] for j in range(17)]
    j3 = [[0.1 * j, 1.0 - 0.05 * j, 0.0] for j in range(17)]
    return {"t": t, "reference_frame": 1 + 3 * t, "joints_3d": j3, "joints_2d": j2,
            "candidates": [j3], "selected": 0, "posture_error_deg": 9.5,
            "bone_errors_deg": [9.5] * 16, "flags": ["image_misfit"] if t in (5, 6) else []}


RESULT = {
    "version": 1,
    "reference": {"name": "swing", "frames": 580, "fps": 120.0},
    "video": {"frames": 137, "fps": 30.0, "width": 320, "height": 240},
    "joints": list(JOINTS),
    "camera": {"scale": 100.0, "theta_z_deg": 0.0, "cx": 160.0, "cy": 120.0},
    "frames": [_frame(t) for t in range(71)],
    "segments": [
        {"reference_start": 1, "reference_end": 241, "performer_start": 0,
         "performer_end": 70, "mean_error_deg": 9.5,
         "bone_mean_errors_deg": [1.0] * 10 + [30.0] + [1.0] * 5},
    ],
    "timing_s": {"total": 12.5},
}  # fmt: skip
# frame 5 also says what the video shows there: the right ankle 20 px to the right
_J2 = RESULT["frames"][5]["joints_2d"]
RESULT["frames"][5].update(
    image_best_joints_2d=[[u + 20.0 * (j == 6), v] for j, (u, v) in enumerate(_J2)]
)


def write_atomic(path: Path, data: dict) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data))
    os.replace(tmp, path)


def status(work_dir: str, state: str, progress: float, stage: str = "alignment") -> None:
    write_atomic(
        Path(work_dir) / "status.json",
        {"state": state, "stage": stage, "progress": progress, "message": stage, "error": None},
    )


def test_upload_queues_a_job_with_safe_paths(client, club_ref, queue, video_file, settings):
    r = upload(client, club_ref, video_file)
    assert r.status_code == 201, r.text
    a = r.json()
    assert a["status"] == "queued" and a["progress"] == 0
    (job,) = queue.jobs
    assert job.analysis_id == a["id"]
    assert Path(job.work_dir) == settings.data_dir.resolve() / "analyses" / a["id"]
    assert Path(job.video_path) == Path(job.work_dir) / "video.mp4"  # not the user's name
    assert Path(job.video_path).stat().st_size == video_file.stat().st_size
    assert Path(job.reference_path).is_file()


def _refused(client, app, club, settings, queue, response, status_code, code):
    assert response.status_code == status_code, response.text
    assert response.json()["error"]["code"] == code
    with app.state.sessionmaker() as s:
        assert s.query(Analysis).count() == 0
    assert queue.jobs == []
    # only the reference uploaded by the fixture remains
    assert all(p.is_dir() or p.name == "reference.bvh" for p in stored_files(settings))
    assert not list((settings.data_dir / "analyses").iterdir())
    assert not list((settings.data_dir / "tmp").iterdir())


def test_not_a_video_is_422_and_leaves_nothing(client, app, club_ref, queue, settings, tmp_path):
    junk = tmp_path / "junk.mp4"
    junk.write_bytes(b"this is not a video at all" * 100)
    r = upload(client, club_ref, junk)
    _refused(client, app, club_ref, settings, queue, r, 422, "invalid_video")


def test_truncated_mp4_is_422(client, app, club_ref, queue, settings, video_file, tmp_path):
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(video_file.read_bytes()[: video_file.stat().st_size // 2])
    r = upload(client, club_ref, cut)
    _refused(client, app, club_ref, settings, queue, r, 422, "invalid_video")


def test_over_the_size_limit_is_413(client, app, club_ref, queue, settings, video_file):
    settings.max_video_bytes = 100_000  # the route's chunk counter (the body limit is fixed)
    r = upload(client, club_ref, video_file)
    _refused(client, app, club_ref, settings, queue, r, 413, "too_large")


def test_body_limit_refuses_before_parsing(tmp_path, queue, video_file):
    from fastapi.testclient import TestClient

    from app.core.config import Settings
    from app.core.queue import get_queue
    from app.main import create_app

    settings = Settings(data_dir=tmp_path / "d", reflect_interval_s=0, max_video_bytes=50_000)
    app = create_app(settings)
    app.dependency_overrides[get_queue] = lambda: queue
    club = make_club(app, "gamma")
    club.reference_id = 1
    with TestClient(app) as c:
        r = upload(c, club, video_file)
    assert r.status_code == 413 and r.json()["error"]["code"] == "too_large"


def test_unknown_reference_or_performer_is_404(client, app, club_ref, queue, settings, video_file):
    r = upload(client, club_ref, video_file, reference_id=9999)
    _refused(client, app, club_ref, settings, queue, r, 404, "not_found")
    r = upload(client, club_ref, video_file, performer_id=9999)
    _refused(client, app, club_ref, settings, queue, r, 404, "not_found")


def test_idempotency_key_returns_the_same_analysis(client, app, club_ref, queue, video_file):
    first = upload(client, club_ref, video_file, key="retry-1")
    again = upload(client, club_ref, video_file, key="retry-1")
    assert (first.status_code, again.status_code) == (201, 200)
    assert first.json()["id"] == again.json()["id"]
    assert len(queue.jobs) == 1
    other = upload(client, club_ref, video_file, key="retry-2")
    assert other.status_code == 201 and other.json()["id"] != first.json()["id"]


def _insert(app, club, n: int, **overrides) -> list[str]:
    ids = []
    start = datetime(2030, 1, 1, tzinfo=UTC)
    with app.state.sessionmaker() as s:
        for i in range(n):
            a = Analysis(
                club_id=club.id, performer_id=club.performer_id, reference_id=club.reference_id,
                video_path="/nonexistent/video.mp4", work_dir=f"/nonexistent/{i}",
                created_at=start + timedelta(days=i), **overrides,
            )  # fmt: skip
            s.add(a)
            s.flush()
            ids.append(a.id)
        s.commit()
    return ids


def test_pagination_and_filters(client, app, club_ref):
    ids = _insert(app, club_ref, 5)
    _insert(app, club_ref, 2, status="failed")
    h = club_ref.headers
    page = client.get("/api/v1/analyses?limit=2&offset=1&status=queued", headers=h).json()
    assert page["total"] == 5 and page["limit"] == 2 and page["offset"] == 1
    assert [a["id"] for a in page["items"]] == [ids[3], ids[2]]  # newest first
    r = client.get("/api/v1/analyses", headers=h, params={"status": "failed"})
    assert r.json()["total"] == 2
    r = client.get(
        "/api/v1/analyses", headers=h,
        params={"created_after": "2030-01-02T00:00:00Z", "created_before": "2030-01-04T00:00:00Z",
                "status": "queued"},
    )  # fmt: skip
    assert sorted(a["id"] for a in r.json()["items"]) == sorted(ids[1:3])
    r = client.get("/api/v1/analyses", headers=h, params={"performer_id": 999})
    assert r.json()["total"] == 0
    r = client.get("/api/v1/analyses", headers=h, params={"reference_id": club_ref.reference_id})
    assert r.json()["total"] == 7
    assert client.get("/api/v1/analyses?status=bogus", headers=h).status_code == 422


def test_other_clubs_analysis_is_404(client, app, club_ref, video_file):
    a = upload(client, club_ref, video_file).json()
    other = make_club(app, "beta")
    for suffix in ("", "/result", "/segments", "/events"):
        r = client.get(f"/api/v1/analyses/{a['id']}{suffix}", headers=other.headers)
        assert r.status_code == 404, suffix
    assert (
        client.post(f"/api/v1/analyses/{a['id']}/cancel", headers=other.headers).status_code == 404
    )
    assert client.delete(f"/api/v1/analyses/{a['id']}", headers=other.headers).status_code == 404
    assert client.get("/api/v1/analyses", headers=other.headers).json()["total"] == 0
    assert client.get("/api/v1/analyses/not-a-uuid", headers=club_ref.headers).status_code == 404


def test_progress_is_reflected_and_result_is_409_until_done(client, club_ref, queue, video_file):
    a = upload(client, club_ref, video_file).json()
    work = queue.jobs[0].work_dir
    url = f"/api/v1/analyses/{a['id']}"
    h = club_ref.headers
    r = client.get(url + "/result", headers=h)
    assert r.status_code == 409 and r.json()["error"]["details"]["status"] == "queued"
    status(work, "running", 0.4)
    got = client.get(url, headers=h).json()
    assert (got["status"], got["stage"], got["progress"]) == ("running", "alignment", 0.4)
    assert client.get(url + "/segments", headers=h).status_code == 409
    write_atomic(Path(work) / "result.json", RESULT)
    r = client.get(url + "/result", headers=h)
    assert r.status_code == 200 and r.json() == RESULT
    lean = client.get(url + "/result?candidates=false", headers=h).json()
    assert all("candidates" not in f and "selected" not in f for f in lean["frames"])
    assert [f["joints_3d"] for f in lean["frames"]] == [f["joints_3d"] for f in RESULT["frames"]]
    got = client.get(url, headers=h).json()
    assert got["status"] == "done" and got["timings"] == {"total": 12.5}
    seg = client.get(url + "/segments", headers=h).json()["segments"][0]
    assert seg["worst_bone"] == "l_elbow->l_wrist" and seg["worst_bone_error_deg"] == 30.0
    assert seg["tempo_ratio"] == pytest.approx((70 / 30) / (240 / 120))
    assert seg["misfit_frames"] == 2  # frames whose posture the video does not confirm
    assert seg["misfit_bones"] == ["r_knee->r_ankle"]  # frame 5's ankle is elsewhere
    status(work, "running", 0.1)  # a final state in the database is never undone
    assert client.get(url, headers=h).json()["status"] == "done"


def test_the_first_segments_show_while_the_analysis_runs(client, club_ref, queue, video_file):
    a = upload(client, club_ref, video_file).json()
    work = queue.jobs[0].work_dir
    url, h = f"/api/v1/analyses/{a['id']}/provisional", club_ref.headers
    r = client.get(url, headers=h)
    assert r.status_code == 409 and r.json()["error"]["code"] == "not_ready"
    status(work, "running", 0.6, stage="candidates")
    assert client.get(url, headers=h).status_code == 409  # no whole segment done yet
    covered = {"frames": 71, "video_frames": 137, "segments": 1, "reference_segments": 3}
    write_atomic(Path(work) / "provisional.json", RESULT | {"provisional": covered})
    got = client.get(url, headers=h).json()
    assert got["provisional"] == covered
    (seg,) = got["segments"]
    assert seg["worst_bone"] == "left forearm" and seg["performer_end"] == 70
    write_atomic(Path(work) / "provisional.json", {"frames": "half-written"})
    r = client.get(url, headers=h)
    assert r.status_code == 500 and r.json()["error"]["code"] == "bad_result"
    write_atomic(Path(work) / "result.json", RESULT)
    status(work, "done", 1.0, stage="select")
    r = client.get(url, headers=h)
    assert r.status_code == 409 and r.json()["error"]["code"] == "done"


def test_what_the_first_frame_shows_is_reflected_while_it_runs(client, club_ref, queue, video_file):
    a = upload(client, club_ref, video_file).json()
    work = queue.jobs[0].work_dir
    url, h = f"/api/v1/analyses/{a['id']}", club_ref.headers
    assert client.get(url, headers=h).json()["warnings"] is None  # stages 0-2 not done yet
    status(work, "running", 0.4, stage="candidates")
    feet = "Your feet are out of the picture: step back."
    write_atomic(Path(work) / "framing.json", {"problems": [feet]})
    assert client.get(url, headers=h).json()["warnings"] == [feet]
    write_atomic(Path(work) / "framing.json", {"problems": []})
    assert client.get(url, headers=h).json()["warnings"] == []
    write_atomic(Path(work) / "framing.json", {"problems": "not a list"})
    assert client.get(url, headers=h).json()["warnings"] == []  # a bad file changes nothing


def test_failed_status_is_reflected(client, club_ref, queue, video_file):
    a = upload(client, club_ref, video_file).json()
    write_atomic(
        Path(queue.jobs[0].work_dir) / "status.json",
        {"state": "failed", "stage": "calibration", "progress": 0.2, "message": "",
         "error": "no body found in the first frame"},
    )  # fmt: skip
    got = client.get(f"/api/v1/analyses/{a['id']}", headers=club_ref.headers).json()
    assert got["status"] == "failed" and "no body" in got["error"]


def test_cancel_and_delete(client, club_ref, queue, video_file, settings):
    a = upload(client, club_ref, video_file).json()
    url = f"/api/v1/analyses/{a['id']}"
    r = client.post(url + "/cancel", headers=club_ref.headers)
    assert r.status_code == 200 and r.json()["status"] == "cancelled"
    assert queue.revoked == ["task-1"]
    assert client.post(url + "/cancel", headers=club_ref.headers).status_code == 409
    assert client.delete(url, headers=club_ref.headers).status_code == 204
    assert client.get(url, headers=club_ref.headers).status_code == 404
    assert not Path(queue.jobs[0].work_dir).exists()


def test_events_stream_progress_and_end(client, club_ref, queue, video_file):
    a = upload(client, club_ref, video_file).json()
    work = queue.jobs[0].work_dir
    status(work, "running", 0.25)

    def worker():
        time.sleep(0.3)
        status(work, "running", 0.75, stage="candidates")
        time.sleep(0.3)
        status(work, "failed", 0.75, stage="candidates")

    t = threading.Thread(target=worker)
    t.start()
    events = []
    with client.stream("GET", f"/api/v1/analyses/{a['id']}/events", headers=club_ref.headers) as r:
        assert r.status_code == 200
        assert r.headers["content-type"].startswith("text/event-stream")
        event = None
        for line in r.iter_lines():
            if line.startswith("event: "):
                event = line[7:]
            elif line.startswith("data: "):
                events.append((event, json.loads(line[6:])))
    t.join()
    progress = [(d["status"], d["progress"]) for e, d in events if e == "progress"]
    assert progress == [("running", 0.25), ("running", 0.75), ("failed", 0.75)]
    assert events[-1] == ("end", {"status": "failed"})


class _Receiver(BaseHTTPRequestHandler):
    received: list = []
    fail_first = 1

    def do_POST(self):  # noqa: N802
        body = self.rfile.read(int(self.headers["Content-Length"]))
        if _Receiver.fail_first > 0:  # the first delivery fails: the sender must retry
            _Receiver.fail_first -= 1
            self.send_response(503)
        else:
            _Receiver.received.append((dict(self.headers), body))
            self.send_response(204)
        self.end_headers()

    def log_message(self, *args):
        pass


@pytest.mark.settings(webhook_allow_private=True)  # the receiver listens on loopback
def test_webhook_is_signed_and_retried(client, app, club_ref, queue, video_file):
    server = HTTPServer(("127.0.0.1", 0), _Receiver)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        url = f"http://127.0.0.1:{server.server_port}/hook"
        r = client.patch("/api/v1/club", headers=club_ref.headers, json={"webhook_url": url})
        assert r.status_code == 200
        secret = r.json()["webhook_secret"]
        assert secret
        a = upload(client, club_ref, video_file).json()
        write_atomic(Path(queue.jobs[0].work_dir) / "result.json", RESULT)
        client.get(f"/api/v1/analyses/{a['id']}", headers=club_ref.headers)
        client.get(f"/api/v1/analyses/{a['id']}", headers=club_ref.headers)  # no second send
        app.state.notifier.wait(timeout=10)
        time.sleep(0.1)
    finally:
        server.shutdown()
    assert len(_Receiver.received) == 1
    headers, body = _Receiver.received[0]
    signature, timestamp = headers["X-Coach-Signature"], headers["X-Coach-Timestamp"]
    assert verify_webhook(body, secret, signature, timestamp)
    assert not verify_webhook(body + b" ", secret, signature, timestamp)
    payload = json.loads(body)
    assert payload["event"] == "analysis.done" and payload["analysis"]["id"] == a["id"]
    assert payload["delivery_id"] == headers["X-Coach-Delivery"]


@pytest.mark.settings(webhook_allow_private=True)
def test_a_cancelled_analysis_is_announced_too(client, app, club_ref, queue, video_file):
    server = HTTPServer(("127.0.0.1", 0), _Receiver)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    _Receiver.received, _Receiver.fail_first = [], 0
    try:
        url = f"http://127.0.0.1:{server.server_port}/hook"
        client.patch("/api/v1/club", headers=club_ref.headers, json={"webhook_url": url})
        a = upload(client, club_ref, video_file).json()
        r = client.post(f"/api/v1/analyses/{a['id']}/cancel", headers=club_ref.headers)
        assert r.status_code == 200
        app.state.notifier.wait(timeout=10)
        time.sleep(0.1)
    finally:
        server.shutdown()
    events = [json.loads(body)["event"] for _, body in _Receiver.received]
    assert events == ["analysis.cancelled"]


def test_every_list_has_the_same_envelope(client, club_ref, video_file):
    upload(client, club_ref, video_file)
    for path in ("/analyses", "/references", "/performers", "/keys"):
        r = client.get(f"/api/v1{path}?limit=1", headers=club_ref.headers)
        assert r.status_code == 200, path
        page = r.json()
        assert set(page) == {"items", "total", "limit", "offset"}, path
        assert page["limit"] == 1 and len(page["items"]) == 1 and page["total"] >= 1, path


def test_api_docs_say_what_one_camera_measures(client):
    from engine.report import ONE_CAMERA_NOTE

    paths = client.get("/api/v1/openapi.json").json()["paths"]
    for what in ("result", "segments"):
        assert paths[f"/api/v1/analyses/{{analysis_id}}/{what}"]["get"]["description"] == (
            ONE_CAMERA_NOTE
        ), what
