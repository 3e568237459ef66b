"""Browser test fixtures: the real app (`coach serve`, embedded worker, fast engine preset) in
a subprocess on a free port with a tmp data dir, and Debian's Chromium driven by Playwright.

A finished analysis for most tests comes from ``engine.pipeline.analyze`` run once on a
12-frame clip (session-scoped) and inserted as a database row; the upload test goes through
the real page, the real API and the real worker.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
import uuid
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.conftest import BENCH_CASES, CHROMIUM, CMU, REPO

SCREENSHOTS = REPO / "artifacts" / "screenshots"
SOURCE_VIDEO = BENCH_CASES / "P1_warp_64_29" / "video.mp4"
PASSWORD = "performer-password"
COACH = ("coach@example.com", "coach-demo-password")  # seeded by `coach serve` in development


def pytest_collection_modifyitems(items):
    reason = None
    if not CHROMIUM.exists():
        reason = "/usr/bin/chromium is missing (apt-get install chromium)"
    else:
        try:
            import playwright.sync_api  # noqa: F401
        except ImportError:
            reason = "the playwright Python package is not installed"
    if not (SOURCE_VIDEO.exists() and (CMU / "64_29.bvh").exists()):
        reason = reason or "../shared/bench and ../shared/data are not beside the clone"
    for item in items:
        if "tests/browser" in str(item.fspath):
            item.add_marker(pytest.mark.browser)
            if reason:
                item.add_marker(pytest.mark.skip(reason=reason))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="session")
def clip(tmp_path_factory) -> Path:
    """12 frames (every 5th of the first 60, 6 fps) of a synthetic golf case, H.264."""
    from engine.io.encode import write_video
    from engine.io.video import read_video

    v = read_video(SOURCE_VIDEO, height=0, max_frames=60)
    path = tmp_path_factory.mktemp("clip") / "swing.mp4"
    write_video(path, v.frames[::5], v.fps / 5)
    return path


@pytest.fixture(scope="session")
def clip_result(clip: Path) -> dict:
    from engine.pipeline import analyze
    from engine.settings import Settings

    return analyze(CMU / "64_29.bvh", clip, Settings.from_dict({"preset": "fast"}))


@dataclass
class Server:
    url: str
    data_dir: Path
    process: subprocess.Popen
    club_id: int
    reference_id: int
    performers: dict[str, int]

    def sessions(self):
        from app.core.db import make_engine, make_sessionmaker

        return make_sessionmaker(make_engine(f"sqlite:///{self.data_dir / 'coach.db'}"))

    def add_done_analysis(self, performer: str, clip: Path, result: dict) -> str:
        """A finished analysis row with its folder (as the worker leaves it)."""
        from app.models import Analysis

        aid = str(uuid.uuid4())
        work = self.data_dir / "analyses" / aid
        work.mkdir(parents=True)
        shutil.copyfile(clip, work / "video.mp4")
        (work / "result.json").write_text(json.dumps(result))
        (work / "status.json").write_text(json.dumps(
            {"state": "done", "stage": "done", "progress": 1.0, "message": "", "error": None}))  # fmt: skip  # noqa: E501
        with self.sessions()() as s:
            s.add(Analysis(id=aid, club_id=self.club_id, performer_id=self.performers[performer],
                           reference_id=self.reference_id, video_path=str(work / "video.mp4"),
                           work_dir=str(work), status="done", stage="done", progress=1.0,
                           result_path=str(work / "result.json")))  # fmt: skip
            s.commit()
        return aid


@pytest.fixture(scope="session")
def server(tmp_path_factory) -> Server:
    data = tmp_path_factory.mktemp("coach-data")
    port = _free_port()
    env = dict(os.environ, COACH_DATA_DIR=str(data), COACH_ENGINE_PRESET="fast",
               COACH_SSE_POLL_S="0.3", COACH_REFLECT_INTERVAL_S="1",
               COACH_RATE_LIMIT_PER_S="1000", COACH_RATE_LIMIT_BURST="1000",
               COACH_ENVIRONMENT="development", COACH_BROKER_URL="embedded",
               # the test clips' stage 3 takes seconds: their previews come at any wait
               COACH_PROVISIONAL_MIN_WAIT_S="0", PYOPENGL_PLATFORM="egl")  # fmt: skip
    log = open(data / "serve.log", "wb")  # noqa: SIM115 - closed at teardown
    proc = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve", "--data-dir", str(data), "--port", str(port)],
        cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
    )  # fmt: skip
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 60
    while True:
        try:
            with urllib.request.urlopen(f"{url}/api/v1/health", timeout=2) as r:
                if r.status == 200:
                    break
        except OSError:
            pass
        if proc.poll() is not None or time.monotonic() > deadline:
            log.close()
            raise RuntimeError(f"coach serve did not start:\n{(data / 'serve.log').read_text()}")
        time.sleep(0.3)

    from app import crud

    srv = Server(url, data, proc, 0, 0, {})
    with srv.sessions()() as s:
        club = crud.get_club_by_name(s, "Demo club")
        ref = crud.get_reference_by_name(s, club_id=club.id, name="CMU 64_29 (golf swing)")
        for key, name in (("pat", "Pat Putter"), ("olive", "Olive Iron")):
            u = crud.create_user(s, club_id=club.id, role="performer", email=f"{key}@example.com",
                                 display_name=name, password=PASSWORD)  # fmt: skip
            srv.performers[key] = u.id
        srv.club_id, srv.reference_id = club.id, ref.id
    yield srv
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=15)
    except subprocess.TimeoutExpired:
        pass
    try:
        os.killpg(proc.pid, signal.SIGKILL)  # the group we started: serve and its worker
    except ProcessLookupError:
        pass
    log.close()


@pytest.fixture(scope="session")
def shots() -> Path:
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    return SCREENSHOTS


def analysis_diagnosis(page, server: Server) -> str:
    """What the API says of the analysis the page shows, and the end of the server's log: the
    message of a browser test that waited in vain for a result."""
    aid = page.url.rstrip("/").split("/")[-1]
    status = page.request.get(f"{server.url}/api/v1/analyses/{aid}").text()
    log = (server.data_dir / "serve.log").read_text(errors="replace").splitlines()
    shown = page.locator("#analysis").get_attribute("data-status")
    return f"page status {shown!r}; API: {status}\nserve.log (end):\n" + "\n".join(log[-60:])


def open_done_analysis(server: Server, browser, clip: Path, result: dict, *,
                       performer: str = "pat", width: int = 1280, height: int = 1000):  # fmt: skip
    """A finished analysis of ``performer``, its page open in a new context signed in as them:
    ``(context, page, analysis id)``."""
    aid = server.add_done_analysis(performer, clip, result)
    ctx = browser.new_context(viewport={"width": width, "height": height})
    page = ctx.new_page()
    sign_in(page, server.url, f"{performer}@example.com", next_path=f"/analyses/{aid}")
    return ctx, page, aid


def sign_in(page, base: str, email: str, password: str = PASSWORD, *, next_path: str = "/"):
    page.goto(f"{base}/login?next={next_path}")
    page.get_by_label("Email").fill(email)
    page.get_by_label("Password").fill(password)
    page.get_by_role("button", name="Sign in").click()
    page.wait_for_url(lambda u: "/login" not in u)
