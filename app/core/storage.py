"""The data directory: uploads streamed to disk, reference files, analysis folders.

Layout under ``data_dir``::

    coach.db                  SQLite database (default)
    secret_key                the session secret, generated at first start (mode 0600)
    clock                     touched to read the storage's clock (worker.contract.storage_now)
    tmp/<random>/             uploads being received and checked; removed on failure, and
                              at start when left by a process that died mid-upload
    references/<id>/          reference.bvh
    analyses/<uuid>/          the worker's folder (worker.contract): video.<ext>, status.json,
                              result.json, stages/

File names always come from us; a user's file name never reaches the file system (at most
its suffix, checked against a fixed list).
"""

from __future__ import annotations

import json
import os
import shutil
import time
import uuid
from pathlib import Path

from fastapi import UploadFile

from worker.contract import storage_now

CHUNK_BYTES = 1024 * 1024
VIDEO_SUFFIXES = (".mp4", ".mov", ".m4v", ".webm", ".avi", ".mkv")


class UploadTooLarge(Exception):
    def __init__(self, limit: int) -> None:
        super().__init__(f"the upload is larger than the limit of {limit} bytes")
        self.limit = limit


class Storage:
    def __init__(self, data_dir: Path) -> None:
        self.root = Path(data_dir).resolve()
        for sub in ("tmp", "references", "analyses"):
            (self.root / sub).mkdir(parents=True, exist_ok=True)

    # ---- uploads
    def clean_tmp(self, older_than_s: float) -> int:
        """Remove uploads left in ``tmp/`` by a process that died while receiving them.

        Only those untouched for ``older_than_s``: other API processes sharing this data
        directory may be receiving theirs right now. Returns how many were removed.
        """
        # The storage's clock, as other processes' files are stamped by it.
        cutoff = (storage_now(self.root) or time.time()) - older_than_s
        stale = [p for p in (self.root / "tmp").iterdir() if p.stat().st_mtime < cutoff]
        for path in stale:
            self.remove(path)
        return len(stale)

    def new_tmp_dir(self) -> Path:
        path = self.root / "tmp" / uuid.uuid4().hex
        path.mkdir(parents=True)
        return path

    async def receive(self, upload: UploadFile, dest: Path, max_bytes: int) -> int:
        """Copy ``upload`` to ``dest`` in 1 MiB chunks; raise :class:`UploadTooLarge` past
        ``max_bytes`` (``dest`` is removed then). Returns the size in bytes."""
        size = 0
        try:
            with open(dest, "wb") as out:
                while chunk := await upload.read(CHUNK_BYTES):
                    size += len(chunk)
                    if size > max_bytes:
                        raise UploadTooLarge(max_bytes)
                    out.write(chunk)
        except BaseException:
            dest.unlink(missing_ok=True)
            raise
        return size

    @staticmethod
    def remove(path: Path | str | None) -> None:
        if path is None:
            return
        p = Path(path)
        if p.is_dir():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)

    # ---- places
    def reference_dir(self, reference_id: int) -> Path:
        return self.root / "references" / str(int(reference_id))

    def analysis_dir(self, analysis_id: str) -> Path:
        return self.root / "analyses" / str(uuid.UUID(analysis_id))

    def capture_dir(self, capture_id: str) -> Path:
        return self.root / "captures" / str(uuid.UUID(capture_id))

    @staticmethod
    def video_suffix(filename: str | None) -> str:
        suffix = Path(filename or "").suffix.lower()
        return suffix if suffix in VIDEO_SUFFIXES else ".mp4"

    @staticmethod
    def move(src: Path, dest: Path) -> Path:
        dest.parent.mkdir(parents=True, exist_ok=True)
        os.replace(src, dest)
        return dest

    @staticmethod
    def share(src: Path, dest: Path) -> Path:
        """``src`` also at ``dest``: a hard link (no second copy of a video) where the file
        system allows, a copy elsewhere. Each analysis folder then owns its file, so
        deleting one analysis never takes another's video."""
        dest.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.link(src, dest)
        except OSError:
            shutil.copyfile(src, dest)
        return dest

    # ---- worker outputs (read side of worker.contract)
    @staticmethod
    def read_json(path: Path) -> dict | None:
        """A JSON object file, or None if it is missing or not (yet) valid."""
        try:
            with open(path, encoding="utf-8") as f:
                data = json.load(f)
        except (OSError, ValueError):
            return None
        return data if isinstance(data, dict) else None
