"""Reference-free captures through the API (issue 23): upload, the worker's capture, its
questions and answers, BVH/CSV downloads, "use as reference", and the refusals a user meets.
The worker step runs the real engine (``worker.capture.run_capture``) on the recorded job."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.core.config import Settings  # noqa: F401 (the fixtures' type)
from engine.errors import RegistrationFailed
from engine.io.bvh import load_reference
from tests.app.conftest import make_club
from tests.app.test_reference_mapping import short_video  # noqa: F401 (fixture)
from worker.capture import run_capture
from worker.contract import CaptureFolder, CaptureJob


def create(client, club, video, **form):
    data = {"performer_id": club.performer_id} | form
    with open(video, "rb") as f:
        return client.post("/api/v1/captures", headers=club.headers, data=data,
                           files={"video": ("best swing.mp4", f, "video/mp4")})  # fmt: skip


@pytest.fixture
def done(client, club, queue, short_video):  # noqa: F811
    r = create(client, club, short_video, height_m="1.8")
    assert r.status_code == 201, r.text
    (job,) = queue.jobs
    run_capture(job)
    return r.json()["id"], job


def test_a_capture_runs_and_its_motion_downloads(client, club, queue, short_video, tmp_path):  # noqa: F811
    r = create(client, club, short_video, height_m="1.8")
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["status"] == "queued" and body["name"] == "best swing.mp4"
    assert r.headers["Location"] == f"/api/v1/captures/{body['id']}"
    (job,) = queue.jobs
    assert isinstance(job, CaptureJob) and job.height_m == pytest.approx(1.8)
    assert client.get(f"/api/v1/captures/{body['id']}/motion.bvh",
                      headers=club.headers).status_code == 409  # fmt: skip
    run_capture(job)
    got = client.get(f"/api/v1/captures/{body['id']}", headers=club.headers).json()
    assert got["status"] == "done" and got["frames"] == 16 and got["progress"] == 1.0
    assert got["message"].startswith("captured 16 frames")
    for skeleton, profile in (("cmu", "cmu"), ("coach", "coach")):
        r = client.get(f"/api/v1/captures/{body['id']}/motion.bvh?skeleton={skeleton}",
                       headers=club.headers)  # fmt: skip
        assert r.status_code == 200
        (tmp_path / f"{skeleton}.bvh").write_bytes(r.content)
        ref = load_reference(tmp_path / f"{skeleton}.bvh", normalise_heading=False)
        assert ref.profile == profile and ref.motion.joints.shape == (16, 17, 3)
    csv = client.get(f"/api/v1/captures/{body['id']}/angles.csv", headers=club.headers).text
    assert csv.splitlines()[0].startswith("t,time_s,hip_x_m") and len(csv.splitlines()) == 17
    listed = client.get("/api/v1/captures", headers=club.headers).json()
    assert listed["total"] == 1 and listed["items"][0]["id"] == body["id"]


def test_answers_run_the_capture_again_with_them(client, club, queue, done):
    capture_id, job = done
    folder = CaptureFolder(job.work_dir)
    summary = json.loads(folder.summary.read_text())
    # a question, as the engine words them (the clip may ask none of its own)
    question = {"id": "l_forearm@2-9", "segment": "l_forearm", "frames": [2, 9],
                "chosen": "towards", "margin": 0.5, "text": "Is the left forearm ...?"}  # fmt: skip
    folder.summary.write_text(json.dumps(summary | {"questions": [question]}))
    url = f"/api/v1/captures/{capture_id}/answers"
    r = client.post(url, headers=club.headers, json={"answers": {"r_shin@0-3": "away"}})
    assert r.status_code == 422 and "did not ask r_shin@0-3" in r.json()["error"]["message"]
    r = client.post(url, headers=club.headers, json={"answers": {"l_forearm@2-9": "sideways"}})
    assert r.status_code == 422
    r = client.post(url, headers=club.headers, json={"answers": {"l_forearm@2-9": "away"}})
    assert r.status_code == 202, r.text
    again = queue.jobs[-1]
    assert again.answers == {"l_forearm@2-9": 1}
    assert client.post(url, headers=club.headers,
                       json={"answers": {"l_forearm@2-9": "away"}}).status_code == 409  # fmt: skip
    run_capture(again)
    cap = json.loads(folder.summary.read_text())
    assert cap["answers"] == {"l_forearm@2-9": 1}
    lines = folder.csv.read_text().splitlines()
    assert len(lines) == 17


def test_a_capture_becomes_a_reference(client, club, app, done):
    capture_id, _ = done
    r = client.post(f"/api/v1/captures/{capture_id}/reference", headers=club.headers,
                    json={"name": "Our best player"})  # fmt: skip
    assert r.status_code == 201, r.text
    ref = r.json()
    assert ref["name"] == "Our best player" and ref["frames"] == 16
    assert client.get(f"/api/v1/references/{ref['id']}", headers=club.headers).status_code == 200
    got = client.get(f"/api/v1/captures/{capture_id}", headers=club.headers).json()
    assert got["reference_id"] == ref["id"] and got["status"] == "done"


def test_refusals_a_user_meets(client, club, app, queue, short_video, tmp_path):  # noqa: F811
    r = create(client, club, short_video, height_m="3.5")
    assert r.status_code == 422
    bad = tmp_path / "notes.mp4"
    bad.write_bytes(b"these are not the frames you are looking for" * 100)
    r = create(client, club, bad)
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_video"
    assert client.get("/api/v1/captures/not-a-uuid", headers=club.headers).status_code == 404
    r = create(client, club, short_video)
    capture_id = r.json()["id"]
    assert client.delete(f"/api/v1/captures/{capture_id}",
                         headers=club.headers).status_code == 409  # fmt: skip
    other = make_club(app, "beta")
    assert client.get(f"/api/v1/captures/{capture_id}", headers=other.headers).status_code == 404
    assert client.get("/api/v1/captures", headers=other.headers).json()["total"] == 0


def test_a_video_without_a_person_fails_with_its_reason(client, club, queue, tmp_path):
    import cv2

    wall = tmp_path / "wall.mp4"
    out = cv2.VideoWriter(str(wall), cv2.VideoWriter_fourcc(*"mp4v"), 25, (160, 120))
    for i in range(30):
        out.write(np.full((120, 160, 3), 80 + i, np.uint8))
    out.release()
    r = create(client, club, wall)
    assert r.status_code == 201, r.text
    with pytest.raises(RegistrationFailed):
        run_capture(queue.jobs[-1])
    got = client.get(f"/api/v1/captures/{r.json()['id']}", headers=club.headers).json()
    assert got["status"] == "failed" and "could not find a person" in got["error"]
    assert client.delete(f"/api/v1/captures/{got['id']}", headers=club.headers).status_code == 204
    assert not CaptureFolder(queue.jobs[-1].work_dir).work_dir.exists()
