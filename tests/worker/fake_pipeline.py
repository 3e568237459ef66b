"""A stand-in for :mod:`engine.pipeline` with the same API, controllable timing and failures.

Used by the unit tests (passed as ``pipeline=``) and by integration tests that need a stage of
known length (their workers run ``celery -A tests.worker.fake_app``). Settings it reads:
``fake_frames`` (video frames, 12), ``fake_seconds_per_frame`` (0), ``fake_fail`` ("invalid"
raises InvalidInput in prepare, "registration" RegistrationFailed in select), ``fake_die``
("process": stage 3 SIGKILLs the pool process running it, as the OOM killer would; "worker":
the whole worker, pool and main process, as a lost machine would). Each falls back to the
environment variable ``FAKE_<NAME>`` (``FAKE_FRAMES``, ...), so a job queued by the API's own
code (which sends no fake settings) can be steered from the worker's environment.
The result is a deterministic function of the inputs' bytes, so runs can be compared.
"""

from __future__ import annotations

import hashlib
import os
import signal
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from engine.errors import InvalidInput, RegistrationFailed

CALLS: list[tuple] = []  # (function, detail) in the calling process; unit tests inspect it


class Settings(dict):
    """The fake's settings: the job's dict as given (the worker parses it with this)."""

    @classmethod
    def from_dict(cls, d):
        return cls(d or {})


def parse_domain(doc):
    return dict(doc)


def _settings(settings):
    env = {
        f"fake_{name}": os.environ[f"FAKE_{name.upper()}"]
        for name in ("frames", "seconds_per_frame", "fail", "die")
        if os.environ.get(f"FAKE_{name.upper()}")
    }
    return env | dict(settings or {})


def _die(how):
    if how == "worker":
        os.killpg(os.getpgrp(), signal.SIGKILL)  # the worker was started in its own group
    os.kill(os.getpid(), signal.SIGKILL)


def _sleep_progress(stage, n, seconds_per_frame, on_progress):
    for i in range(n):
        if seconds_per_frame:
            time.sleep(seconds_per_frame)
        if on_progress is not None:
            on_progress(stage, (i + 1) / n)


@dataclass
class Prepared:
    seed: np.ndarray  # Shape (T',)
    settings_seconds: float = 0.0
    framing: tuple[str, ...] = ()  # the engine's first-frame advice: none here

    def save(self, path):
        np.savez(path, seed=self.seed, settings_seconds=self.settings_seconds)

    @classmethod
    def load(cls, path):
        with np.load(path) as z:
            return cls(seed=z["seed"], settings_seconds=float(z["settings_seconds"]))

    def chunks(self, n_chunks):
        edges = np.linspace(0, len(self.seed), n_chunks + 1).round().astype(int)
        return [range(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


@dataclass
class CandidateChunk:
    frames: np.ndarray  # Shape (F,)
    values: np.ndarray  # Shape (F,)

    def save(self, path):
        np.savez(path, frames=self.frames, values=self.values)

    @classmethod
    def load(cls, path):
        with np.load(path) as z:
            return cls(frames=z["frames"], values=z["values"])


def prepare(reference_path, video_path, settings=None, *, domain=None, mapping=None,
            units_to_m=None, on_progress=None):  # fmt: skip
    s = _settings(settings)
    CALLS.append(("prepare", str(video_path)))
    if s.get("fake_fail") == "invalid":
        raise InvalidInput(f"video {Path(video_path).name} has no frames")
    digest = hashlib.sha256(
        Path(reference_path).read_bytes()[:4096] + Path(video_path).read_bytes()[:4096]
    ).digest()
    n = int(s.get("fake_frames", 12))
    seed = np.frombuffer((digest * (n // len(digest) + 1))[:n], dtype=np.uint8).astype(float)
    spf = float(s.get("fake_seconds_per_frame", 0.0))
    _sleep_progress("foreground", n, spf / 2, on_progress)
    _sleep_progress("alignment", n, spf / 2, on_progress)
    return Prepared(seed=seed, settings_seconds=spf)


def candidates(prepared, frames, settings=None, *, on_progress=None):
    CALLS.append(("candidates", (frames.start, frames.stop)))
    if how := _settings(settings).get("fake_die"):
        _die(how)
    idx = np.arange(frames.start, frames.stop)
    _sleep_progress("candidates", max(len(idx), 1), prepared.settings_seconds, on_progress)
    return CandidateChunk(frames=idx, values=prepared.seed[idx] * 2 + 1)


def select(prepared, chunks, settings=None, *, on_progress=None):
    s = _settings(settings)
    CALLS.append(("select", len(chunks)))
    if s.get("fake_fail") == "registration":
        raise RegistrationFailed("no consistent temporal correspondence was found")
    frames = np.concatenate([c.frames for c in chunks])
    values = np.concatenate([c.values for c in chunks])
    if on_progress is not None:
        on_progress("selection", 1.0)
    return {
        "version": 1,
        "frames": [
            {"t": int(t), "posture_error_deg": float(v)}
            for t, v in zip(frames, values, strict=True)
        ],
        "segments": [],
    }
