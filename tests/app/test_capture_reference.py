"""A capture (issue 23) is a reference like any mocap file: its BVH uploads to the club's
library through the API and an analysis against it completes."""

from __future__ import annotations

import dataclasses
import json

from engine.capture import capture
from engine.capture.export import write_capture_bvh
from tests.app.conftest import upload
from tests.app.test_reference_mapping import CHEAP, short_video  # noqa: F401 (fixture)
from tests.engine.capture.test_capture import seen_by_model, squat


def test_a_captured_motion_is_used_as_a_reference(client, club, queue, tmp_path, short_video):  # noqa: F811
    from engine import pipeline
    from worker import jobs

    cap = capture(seen_by_model(squat()), 30.0, (640, 800))
    bvh = write_capture_bvh(cap, tmp_path / "captured.bvh")  # CMU names, as exported
    with open(bvh, "rb") as f:
        r = client.post(
            "/api/v1/references",
            headers=club.headers,
            files={"file": ("captured.bvh", f)},
            data={"name": "our best squat"},
        )
    assert r.status_code == 201, r.text
    ref = r.json()
    assert ref["name"] == "our best squat"
    assert ref["frames"] == cap.joints.shape[0]
    club.reference_id = ref["id"]
    assert upload(client, club, short_video).status_code in (201, 202)
    (job,) = queue.jobs
    job = dataclasses.replace(job, settings=CHEAP)
    result = json.loads(jobs.run_all(job, 1, pipeline=pipeline).read_text())
    assert jobs.read_status(job.work_dir)["state"] == "done"
    assert result["reference"]["frames"] == cap.joints.shape[0]
    assert len(result["frames"]) == 16
