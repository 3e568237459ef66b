"""Celery's filesystem result backend with whole-file writes (the embedded mode's result store).

The stock :class:`celery.backends.filesystem.FilesystemBackend` writes a result by truncating
its file and writing in place. Two stage-3 parts publishing progress for their root task at
the same moment then interleave: one truncates, both write from offset 0, and the file holds
the shorter document followed by the tail of the longer one. The next reader fails with
``DecodeError: Extra data`` and, since progress is published from inside the stage, the part
and its analysis failed with it (seen in CI: an analysis "internal error in candidates"). Here
every write goes to a temporary file first and is renamed over the result, so a reader sees
one whole document, the last written.
"""

from __future__ import annotations

import os
import threading

from celery.backends.filesystem import FilesystemBackend
from kombu.utils.encoding import ensure_bytes

#: How ``COACH_RESULT_BACKEND``'s ``file://`` URLs are given to Celery (``module:Class+url``).
BACKEND = "worker.result_backend:AtomicFilesystemBackend"


class AtomicFilesystemBackend(FilesystemBackend):
    """:class:`FilesystemBackend` whose ``set`` replaces the file atomically."""

    def set(self, key, value) -> None:  # type: ignore[no-untyped-def]
        path = os.fsdecode(self._filename(key))  # keys and paths may be bytes
        tmp = f"{path}.{os.getpid()}.{threading.get_ident()}.tmp"
        try:
            with self.open(tmp, "wb") as out:
                out.write(ensure_bytes(value))
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)


def celery_url(result_backend: str) -> str:
    """The result backend URL as Celery should load it: ``file://`` through this module."""
    if result_backend.startswith("file://"):
        return f"{BACKEND}+{result_backend}"
    return result_backend
