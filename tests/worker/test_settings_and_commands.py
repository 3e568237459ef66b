"""worker.settings from the environment, `coach worker` argument handling, the Celery config."""

from __future__ import annotations

import argparse

import pytest

from worker import commands
from worker.settings import WorkerSettings


def test_embedded_is_the_default(tmp_path):
    s = WorkerSettings.from_env({"COACH_DATA_DIR": str(tmp_path)})
    assert s.embedded and s.broker_url.startswith("filesystem://")
    assert s.result_backend == f"file://{tmp_path / 'celery' / 'results'}"


def test_redis_broker_is_also_the_result_backend(tmp_path):
    s = WorkerSettings.from_env(
        {"COACH_DATA_DIR": str(tmp_path), "COACH_BROKER_URL": "redis://h:6379/0"}
    )
    assert not s.embedded and s.result_backend == "redis://h:6379/0"


def test_visibility_timeout_exceeds_every_hard_limit(tmp_path):
    s = WorkerSettings.from_env({"COACH_DATA_DIR": str(tmp_path)})
    longest = max(hard for _, hard in s.limits_s.values())
    assert s.visibility_timeout_s > longest + 600  # + the longest retry countdown


def test_limits_from_env_and_validation(tmp_path):
    s = WorkerSettings.from_env(
        {"COACH_DATA_DIR": str(tmp_path), "COACH_PREPARE_SOFT_S": "5", "COACH_PREPARE_HARD_S": "9"}
    )
    assert s.limits_for("prepare") == (5, 9)
    with pytest.raises(ValueError, match="COACH_SELECT_HARD_S"):
        WorkerSettings.from_env({"COACH_SELECT_SOFT_S": "10", "COACH_SELECT_HARD_S": "10"})
    with pytest.raises(ValueError, match="COACH_CHUNKS"):
        WorkerSettings.from_env({"COACH_CHUNKS": "0"})
    with pytest.raises(ValueError, match="COACH_VISIBILITY_TIMEOUT_S"):
        WorkerSettings.from_env({"COACH_VISIBILITY_TIMEOUT_S": "soon"})
    assert WorkerSettings.from_env({}).provisional_min_wait_s == 5.0
    assert WorkerSettings.from_env(
        {"COACH_PROVISIONAL_MIN_WAIT_S": "0"}
    ).provisional_min_wait_s == 0.0
    with pytest.raises(ValueError, match="COACH_PROVISIONAL_MIN_WAIT_S"):
        WorkerSettings.from_env({"COACH_PROVISIONAL_MIN_WAIT_S": "-1"})


def test_heartbeat_settings_from_env_and_validation(tmp_path):
    s = WorkerSettings.from_env({"COACH_DATA_DIR": str(tmp_path)})
    assert (s.heartbeat_s, s.lost_after_s, s.max_crashes) == (5.0, 60.0, 2)
    s = WorkerSettings.from_env({"COACH_HEARTBEAT_S": "0.5", "COACH_LOST_AFTER_S": "3"})
    assert (s.heartbeat_s, s.lost_after_s) == (0.5, 3.0)
    with pytest.raises(ValueError, match="COACH_LOST_AFTER_S"):  # a missed beat is no loss
        WorkerSettings.from_env({"COACH_HEARTBEAT_S": "30", "COACH_LOST_AFTER_S": "60"})
    with pytest.raises(ValueError, match="COACH_MAX_CRASHES"):
        WorkerSettings.from_env({"COACH_MAX_CRASHES": "0"})


def test_celery_conf_for_long_idempotent_tasks():
    from worker.celery_app import app

    assert app.conf.task_acks_late and app.conf.task_reject_on_worker_lost
    assert app.conf.worker_prefetch_multiplier == 1
    import worker.tasks as tasks

    for task in (tasks.analyze, tasks.prepare, tasks.candidates, tasks.select):
        assert 0 < task.soft_time_limit < task.time_limit


def test_coach_worker_command_arguments():
    parser = argparse.ArgumentParser()
    commands.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["worker", "--concurrency", "3", "--loglevel", "debug"])
    assert args.func is commands.run
    assert commands.worker_argv(args) == ["worker", "--loglevel", "DEBUG", "--concurrency", "3"]
    with pytest.raises(SystemExit):
        commands.worker_argv(parser.parse_args(["worker", "-c", "0"]))
