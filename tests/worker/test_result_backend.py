"""The embedded mode's result store takes concurrent writers without torn documents."""

from __future__ import annotations

import json
import threading

from worker.result_backend import AtomicFilesystemBackend, celery_url


def _backend(tmp_path) -> AtomicFilesystemBackend:
    from celery import Celery

    app = Celery(set_as_current=False)
    return AtomicFilesystemBackend(app=app, url=f"file://{tmp_path}")


def test_two_writers_and_a_reader_never_see_half_a_document(tmp_path):
    """Two stage-3 parts publish progress for one root task at once (documents of different
    lengths): every read decodes to one of the documents written."""
    backend = _backend(tmp_path)
    docs = [json.dumps({"progress": 0.5, "message": "x" * n}).encode() for n in (40, 400)]
    stop = threading.Event()

    def write(doc: bytes) -> None:
        while not stop.is_set():
            backend.set(b"root", doc)

    writers = [threading.Thread(target=write, args=(d,)) for d in docs]
    for w in writers:
        w.start()
    try:
        seen = set()
        for _ in range(3000):
            raw = backend.get(b"root")
            if raw is not None:
                json.loads(raw)  # raises on a torn document
                seen.add(len(raw))
    finally:
        stop.set()
        for w in writers:
            w.join()
    assert seen <= {len(d) for d in docs} and seen
    assert [p.name for p in tmp_path.iterdir()] == ["root"]  # no temporary file left


def test_file_urls_load_through_the_atomic_backend(tmp_path):
    from celery.app.backends import by_url

    assert celery_url("redis://h:6379/0") == "redis://h:6379/0"
    cls, url = by_url(celery_url(f"file://{tmp_path}"))
    assert cls is AtomicFilesystemBackend and url == f"file://{tmp_path}"
