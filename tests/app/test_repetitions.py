"""A video with several repetitions: the user picks one and it is analysed on its own
(issue 20, item 7). End to end on a real clip: the engine finds the repetitions, the API
starts the chosen one's analysis, the worker's engine analyses exactly its frames."""

from __future__ import annotations

import dataclasses
import json

import pytest

from tests.app.conftest import upload
from tests.app.test_reference_mapping import CHEAP
from tests.conftest import CMU, SHARED

SQUATS = SHARED / "data" / "real" / "squat_front_5fps.mp4"


@pytest.fixture
def squat_club(client, club):
    if not SQUATS.exists() or not (CMU / "64_17.bvh").exists():
        pytest.skip("../shared/data is not beside the clone")
    with open(CMU / "64_17.bvh", "rb") as f:
        r = client.post("/api/v1/references", headers=club.headers,
                        files={"file": ("squat.bvh", f)}, data={"name": "squat"})  # fmt: skip
    assert r.status_code == 201, r.text
    club.reference_id = r.json()["id"]
    return club


def run(job):
    from engine import pipeline
    from worker import jobs

    job = dataclasses.replace(job, settings=CHEAP)
    return json.loads(jobs.run_all(job, 1, pipeline=pipeline).read_text())


def test_another_repetition_is_analysed_on_its_own(client, squat_club, queue):
    club = squat_club
    r = upload(client, club, SQUATS)
    assert r.status_code == 201, r.text
    first_id = r.json()["id"]
    url = f"/api/v1/analyses/{first_id}/repetitions/2"
    assert client.post(url, headers=club.headers).json()["error"]["code"] == "not_ready"
    result = run(queue.jobs[0])
    reps = result["summary"]["repetitions"]
    assert len(reps) >= 2 and reps[0]["analysed"] and not reps[1]["analysed"]

    r = client.post(f"/api/v1/analyses/{first_id}/repetitions/9", headers=club.headers)
    assert r.status_code == 404 and "lists" in r.json()["error"]["message"]
    assert (
        client.post(f"/api/v1/analyses/{first_id}/repetitions/0", headers=club.headers).status_code
        == 422
    )
    other = "00000000-0000-4000-8000-000000000000"
    assert (
        client.post(f"/api/v1/analyses/{other}/repetitions/1", headers=club.headers).status_code
        == 404
    )

    r = client.post(url, headers=club.headers)
    assert r.status_code == 201, r.text
    second = r.json()
    assert (second["frames_start"], second["frames_end"]) == (reps[1]["start"], reps[1]["end"])
    assert r.headers["Location"].endswith(f"/api/v1/analyses/{second['id']}")
    assert "repetition 2 of" in second["message"]
    job = queue.jobs[1]
    assert job.frames == [reps[1]["start"], reps[1]["end"]]
    assert job.video_path != queue.jobs[0].video_path  # its own file: deleting one keeps the other
    again = run(job)
    assert again["video"]["first_frame"] == reps[1]["start"]
    assert len(again["frames"]) == reps[1]["end"] - reps[1]["start"]
    assert again["frames"][0]["t"] == reps[1]["start"]

    assert client.delete(f"/api/v1/analyses/{first_id}", headers=club.headers).status_code == 204
    assert (
        client.get(f"/api/v1/analyses/{second['id']}/video.mp4", headers=club.headers).status_code
        == 200
    )
