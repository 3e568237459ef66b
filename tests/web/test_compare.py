"""Progress over time: the comparison numbers and their endpoints (TestClient, no browser)."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from app.core import compare
from tests.web.test_pages import add_done, env, fake_result, sign_in  # noqa: F401 - fixture


def slower_better(result: dict) -> dict:
    """The same attempt twice as slow (two video frames per reference frame), errors halved
    in the first segment and up in the second."""
    r = copy.deepcopy(result)
    frames = []
    for f in r["frames"]:
        for k in range(2):
            g = copy.deepcopy(f)
            g["t"] = 2 * f["t"] + k
            frames.append(g)
    for g in frames:
        first = g["reference_frame"] < 16
        g["posture_error_deg"] = g["posture_error_deg"] / 2 if first else g["posture_error_deg"] + 5
    r["frames"] = frames
    r["video"]["frames"] = len(frames)
    for s in r["segments"]:
        s["performer_start"], s["performer_end"] = 2 * s["performer_start"], 2 * s["performer_end"]
    r["segments"][0]["mean_error_deg"] = 10.0
    r["segments"][1]["mean_error_deg"] = 60.5
    return r


def test_compare_results_lines_up_on_reference_frames_and_says_the_change():
    a = fake_result()
    b = slower_better(a)
    d = compare.compare_results(a, b, ["backswing", "downswing"])
    # Both curves on the reference's frames: the slower attempt covers the same range.
    assert [p[0] for p in d["curves"]["a"]] == [10 + 2 * t for t in range(8)]
    assert len(d["curves"]["b"]) == 16 and d["curves"]["b"][0][0] == 10.0
    assert d["reference_frames"] == [10.0, 24.0]
    s0, s1 = d["segments"]
    assert s0["name"] == "backswing" and s0["error_change"] == "better"
    assert s0["error_change_deg"] == pytest.approx(-10.0)
    assert s1["error_change"] == "same"  # +0.5 deg is within SAME_ERROR_DEG
    # Twice the video frames at the same fps: twice the expert's time, further from 1.
    assert s0["b"]["tempo_ratio"] == pytest.approx(2 * s0["a"]["tempo_ratio"])
    assert s0["tempo_change"] == "worse"
    assert d["mean"]["a"] == pytest.approx(compare.mean_error_deg(a), abs=1e-3)
    assert d["mean"]["change"] in ("better", "worse", "same")


def test_compare_results_with_a_missing_segment():
    a, b = fake_result(), fake_result()
    b["segments"] = b["segments"][:1]
    d = compare.compare_results(a, b, [])
    assert d["segments"][1]["b"] is None and d["segments"][1]["error_change"] is None
    assert d["segments"][1]["name"] == "segment 2"


def test_history_and_compare_endpoints(env):  # noqa: F811
    app, client, ids, _, settings = env
    first = add_done(app, settings, ids, ids["perf"])
    second = add_done(app, settings, ids, ids["perf"])
    path = settings.data_dir / "analyses" / second / "result.json"
    path.write_text(json.dumps(slower_better(fake_result())))
    others = add_done(app, settings, ids, ids["other"])

    sign_in(client, "c@a.org")
    h = client.get(f"/api/v1/performers/{ids['perf']}/history").json()
    assert [a["id"] for a in h["analyses"]] == [first, second]
    assert all(a["mean_error_deg"] > 0 for a in h["analyses"])
    r = client.get(f"/api/v1/performers/{ids['perf']}/compare", params={"a": first, "b": second})
    assert r.status_code == 200, r.text
    d = r.json()
    assert d["a"]["id"] == first and d["b"]["video"].endswith(f"{second}/video.mp4")
    assert d["segments"][0]["error_change"] == "better"
    assert len(d["curves"]["b"]) == 2 * len(d["curves"]["a"])
    # Another performer's analysis is refused.
    r = client.get(f"/api/v1/performers/{ids['perf']}/compare", params={"a": first, "b": others})
    assert r.status_code == 422
    assert client.get(f"/performers/{ids['perf']}/compare").status_code == 200

    # A performer sees their own progress only.
    sign_in(client, "o@a.org")
    assert client.get(f"/api/v1/performers/{ids['perf']}/history").status_code == 404
    assert client.get(f"/performers/{ids['perf']}/compare").status_code == 404
    assert client.get(f"/api/v1/performers/{ids['other']}/history").status_code == 200


def test_compare_refuses_unfinished_and_different_references(env):  # noqa: F811
    from app import crud
    from app.models import Analysis

    app, client, ids, _, settings = env
    done = add_done(app, settings, ids, ids["perf"])
    other_ref = add_done(app, settings, ids, ids["perf"])
    with app.state.sessionmaker() as s:
        ref = crud.create_reference(s, club_id=ids["club"], name="tai chi")
        ref.bvh_path = s.get(Analysis, done).reference.bvh_path
        s.get(Analysis, other_ref).reference_id = ref.id
        running = Analysis(club_id=ids["club"], performer_id=ids["perf"], reference_id=ids["ref"],
                           video_path="", work_dir=str(Path(settings.data_dir) / "x"),
                           status="running")  # fmt: skip
        s.add(running)
        s.commit()
        running_id = running.id
    sign_in(client, "c@a.org")
    url = f"/api/v1/performers/{ids['perf']}/compare"
    assert client.get(url, params={"a": done, "b": other_ref}).status_code == 422
    assert client.get(url, params={"a": done, "b": running_id}).status_code == 409
