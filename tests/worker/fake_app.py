"""``celery -A tests.worker.fake_app worker``: the real worker app and tasks over the fake engine.

The integration tests of the queue (redelivery, cancellation, progress) need stages of a known
length; they start their worker processes with this module as the app, which gives the tasks
:mod:`tests.worker.fake_pipeline` as their engine (``worker.tasks.ENGINE``).
"""

from tests.worker import fake_pipeline
from worker import tasks
from worker.celery_app import app

tasks.ENGINE = fake_pipeline

__all__ = ["app"]
