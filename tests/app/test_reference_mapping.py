"""A reference whose joints need the club's own mapping is accepted *and* analysed.

Issue 24 named the bug: the upload check read the BVH with the ``mapping`` of the domain
JSON, but the worker's engine read it without, and the analysis failed with "cannot map ...
missing l_hip". The mapping and units now travel in the worker's job as data."""

from __future__ import annotations

import dataclasses
import json

import pytest

from tests.app.conftest import SAMPLE_BVH, upload
from tests.conftest import BENCH_CASES

CHEAP = {
    "preset": "fast",
    "candidates": {"n_samples": 8, "n_iterations": 3, "refine_sweeps": 1, "n_candidates": 4},
}


@pytest.fixture
def renamed_bvh(tmp_path):
    """The CMU bend-down with its left thigh renamed so no name table maps it."""
    if not SAMPLE_BVH.exists():
        pytest.skip("../shared/data/cmu is not beside the clone")
    text = SAMPLE_BVH.read_text().replace("LeftUpLeg", "Thigh_L_custom")
    path = tmp_path / "custom.bvh"
    path.write_text(text)
    return path


@pytest.fixture
def short_video(tmp_path):
    src = BENCH_CASES / "P1_warp_64_29" / "video.mp4"
    if not src.exists():
        pytest.skip("public cases not beside the clone")
    from engine.io.encode import write_video
    from engine.io.video import read_video

    video = read_video(src, height=0, max_frames=64)
    out = tmp_path / "short.mp4"
    write_video(out, video.frames[::4][:16], video.fps)
    return out


def test_a_bvh_that_needs_a_custom_mapping_is_analysed(client, club, queue, renamed_bvh,
                                                       short_video):  # fmt: skip
    from engine import pipeline
    from worker import jobs

    with open(renamed_bvh, "rb") as f:
        r = client.post("/api/v1/references", headers=club.headers,
                        files={"file": ("custom.bvh", f)},
                        data={"name": "custom"})  # fmt: skip
    assert r.status_code == 422, r.text  # without the mapping it cannot be read ...
    assert "l_hip" in r.text
    domain = json.dumps({"mapping": {"l_hip": "Thigh_L_custom"}}).encode()
    with open(renamed_bvh, "rb") as f:
        r = client.post("/api/v1/references", headers=club.headers,
                        files={"file": ("custom.bvh", f), "domain": ("d.json", domain)},
                        data={"name": "custom"})  # fmt: skip
    assert r.status_code == 201, r.text  # ... with it, it is accepted
    club.reference_id = r.json()["id"]
    assert upload(client, club, short_video).status_code in (201, 202)
    (job,) = queue.jobs
    assert job.reference_mapping == {"l_hip": "Thigh_L_custom"}
    job = dataclasses.replace(job, settings=CHEAP)
    result = json.loads(jobs.run_all(job, 1, pipeline=pipeline).read_text())
    assert jobs.read_status(job.work_dir)["state"] == "done"
    assert len(result["frames"]) == 16
