"""Service test fixtures: a real SQLite file in tmp_path and a queue that records jobs."""

from __future__ import annotations

import shutil
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from app import crud
from app.core.config import Settings
from app.core.queue import get_queue
from app.main import create_app
from tests.conftest import BENCH_CASES, CMU

SAMPLE_VIDEO = BENCH_CASES / "P1_warp_64_29" / "video.mp4"
SAMPLE_BVH = CMU / "64_29.bvh"


@dataclass
class RecordingQueue:
    jobs: list = field(default_factory=list)
    revoked: list = field(default_factory=list)

    def enqueue(self, job) -> str:
        self.jobs.append(job)
        return f"task-{len(self.jobs)}"

    def enqueue_capture(self, job) -> str:
        self.jobs.append(job)
        return f"task-{len(self.jobs)}"

    def revoke(self, task_id: str) -> None:
        self.revoked.append(task_id)


@pytest.fixture
def video_file(tmp_path: Path) -> Path:
    if SAMPLE_VIDEO.exists():
        return Path(shutil.copyfile(SAMPLE_VIDEO, tmp_path / "sample.mp4"))
    import cv2
    import numpy as np

    path = tmp_path / "sample.mp4"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 25, (64, 48))
    for i in range(10):
        writer.write(np.full((48, 64, 3), i * 20, np.uint8))
    writer.release()
    return path


@pytest.fixture
def bvh_file() -> Path:
    if not SAMPLE_BVH.exists():
        pytest.skip("../shared/data/cmu is not beside the clone")
    return SAMPLE_BVH


@pytest.fixture
def settings(request: pytest.FixtureRequest, tmp_path: Path) -> Settings:
    """Test settings; ``@pytest.mark.settings(name=value)`` changes some for one test."""
    marker = request.node.get_closest_marker("settings")
    return Settings(
        **{
            "data_dir": tmp_path / "data",
            "reflect_interval_s": 0,
            "sse_poll_s": 0.05,
            "rate_limit_per_s": 1000,
            "rate_limit_burst": 1000,
            "webhook_backoff_s": 0.05,
            "webhook_timeout_s": 2,
        }
        | (marker.kwargs if marker else {})
    )


@pytest.fixture
def queue() -> RecordingQueue:
    return RecordingQueue()


@pytest.fixture
def app(settings: Settings, queue: RecordingQueue):
    app = create_app(settings)
    app.dependency_overrides[get_queue] = lambda: queue
    return app


@pytest.fixture
def client(app):
    with TestClient(app) as c:
        yield c


@dataclass
class ClubFixture:
    id: int
    key: str
    performer_id: int
    reference_id: int | None = None

    @property
    def headers(self) -> dict[str, str]:
        return {"X-API-Key": self.key}


def make_club(app, name: str) -> ClubFixture:
    with app.state.sessionmaker() as session:
        club = crud.create_club(session, name=name)
        session.commit()
        _, key = crud.create_api_key(session, club_id=club.id, name="test")
        performer = crud.create_user(
            session, club_id=club.id, role="performer", email=f"p@{name}.org",
            display_name="Performer",
        )  # fmt: skip
        return ClubFixture(id=club.id, key=key, performer_id=performer.id)


@pytest.fixture
def club(app) -> ClubFixture:
    return make_club(app, "alpha")


@pytest.fixture
def club_ref(client, club: ClubFixture, bvh_file: Path) -> ClubFixture:
    with open(bvh_file, "rb") as f:
        r = client.post(
            "/api/v1/references", headers=club.headers,
            files={"file": ("swing.bvh", f, "application/octet-stream")}, data={"name": "swing"},
        )  # fmt: skip
    assert r.status_code == 201, r.text
    club.reference_id = r.json()["id"]
    return club


def upload(client, club: ClubFixture, video: Path, *, key: str | None = None, **form):
    data = {"reference_id": club.reference_id, "performer_id": club.performer_id} | form
    headers = club.headers | ({"Idempotency-Key": key} if key else {})
    with open(video, "rb") as f:
        return client.post(
            "/api/v1/analyses", headers=headers, data=data,
            files={"video": ("../../etc/My Swing.mp4", f, "video/mp4")},
        )  # fmt: skip


def data_files(settings: Settings, sub: str) -> list[Path]:
    root = settings.data_dir / sub
    return sorted(p for p in root.rglob("*")) if root.exists() else []


def stored_files(settings: Settings) -> list[Path]:
    """Every file the API stored (uploads, references, analysis folders), not the database."""
    return [p for sub in ("tmp", "references", "analyses") for p in data_files(settings, sub)]
