"""docker-compose.yml and the Dockerfile (Docker cannot run here: parse and check them)."""

from __future__ import annotations

import pytest

from tests.conftest import REPO

yaml = pytest.importorskip("yaml")


@pytest.fixture(scope="module")
def compose() -> dict:
    return yaml.safe_load((REPO / "docker-compose.yml").read_text())


def test_compose_has_redis_api_and_scalable_worker(compose):
    services = compose["services"]
    assert set(services) >= {"redis", "api", "worker"}
    api, worker = services["api"], services["worker"]
    assert api["command"][:4] == ["coach", "serve", "--host", "0.0.0.0"]
    assert worker["command"][:2] == ["coach", "worker"]
    # --scale worker=N needs no fixed container name or host port on the worker.
    assert "container_name" not in worker and "ports" not in worker
    assert "redis-server" in services["redis"]["command"]


def test_compose_services_share_settings_and_data(compose):
    services = compose["services"]
    for name in ("api", "worker"):
        env = services[name]["environment"]
        assert env["COACH_BROKER_URL"] == "redis://redis:6379/0"
        assert env["COACH_DATA_DIR"] == "/data"
        assert env["COACH_RESULT_BACKEND"].startswith("redis://redis:6379/")
        assert "coach-data:/data" in services[name]["volumes"]
        assert services[name]["depends_on"]["redis"]["condition"] == "service_healthy"
    assert "coach-data" in compose["volumes"]


def test_dockerfile_installs_rendering_ffmpeg_and_the_project():
    text = (REPO / "Dockerfile").read_text()
    for package in ("libegl1", "libgl1-mesa-dri", "ffmpeg"):
        assert package in text
    assert "pip install" in text and "worker" in text
    assert "PYOPENGL_PLATFORM=egl" in text


def test_compose_env_names_are_read_by_the_worker(compose):
    from worker.settings import WorkerSettings

    env = {
        k: str(v)
        for k, v in compose["services"]["worker"]["environment"].items()
        if "${" not in str(v)
    }
    s = WorkerSettings.from_env(env)
    assert s.broker_url == "redis://redis:6379/0" and not s.embedded
    assert str(s.data_dir) == "/data"
