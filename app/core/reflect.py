"""Worker progress reflected into the database, and completion webhooks.

Workers report only through files in the analysis folder (``worker.contract``): status.json
(replaced atomically) and result.json. The API reads them on every read of an analysis, in
the server-sent-events loop and, so that webhooks fire even when nobody is watching, from a
background :class:`Reflector` thread. A database state that is final (done, failed,
cancelled) is never changed again by what the folder says.
"""

from __future__ import annotations

import json
import logging
import threading
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
from sqlalchemy import update
from sqlalchemy.orm import Session, sessionmaker

from app import crud
from app.core import webhooks
from app.core.compare import mean_error_deg
from app.core.config import Settings
from app.core.security import sign_webhook
from app.core.storage import Storage
from app.models import ANALYSIS_STATES, TERMINAL_STATES, Analysis, utcnow
from app.schemas import AnalysisPublic
from worker.contract import AnalysisFolder
from worker.engine_surface import InvalidInput

log = logging.getLogger("app.reflect")


#: Called with the analysis after this process moved it into a final state.
OnFinal = Callable[[Analysis], None]


def _text(value: Any, limit: int) -> str:
    return str(value)[:limit] if value is not None else ""


def headline_error(result: dict[str, Any]) -> float | None:
    """The mean posture error of a result document, None when it has none or is malformed
    (the result page then says what is wrong with it)."""
    try:
        return mean_error_deg(result)
    except InvalidInput:
        return None


def _fill_headline(session: Session, analysis: Analysis) -> bool:
    """A done analysis from before the headline was kept gets it once, from its result."""
    if analysis.status != "done" or analysis.mean_error_deg is not None:
        return False
    result = Storage.read_json(Path(analysis.result_path)) if analysis.result_path else None
    value = headline_error(result) if isinstance(result, dict) else None
    if value is None:
        return False
    analysis.mean_error_deg = value
    session.commit()
    return True


def reflect(session: Session, analysis: Analysis, *, on_final: OnFinal | None = None) -> bool:
    """Update ``analysis`` from its folder; returns True when the row changed."""
    if analysis.status in TERMINAL_STATES:
        return _fill_headline(session, analysis)
    folder = AnalysisFolder(analysis.work_dir)
    status = Storage.read_json(folder.status) or {}
    result_file = folder.result
    state = status.get("state") if status.get("state") in ANALYSIS_STATES else analysis.status
    values: dict[str, Any] = {
        "status": state,
        "stage": _text(status.get("stage", analysis.stage), 64),
        "message": _text(status.get("message", analysis.message), 1000),
        "error": _text(status["error"], 10000) if status.get("error") else analysis.error,
    }
    framing = Storage.read_json(folder.framing)
    if framing is not None and isinstance(framing.get("problems"), list):
        values["warnings"] = [_text(str(p), 500) for p in framing["problems"][:10]]
    try:
        values["progress"] = min(max(float(status.get("progress", analysis.progress)), 0.0), 1.0)
    except (TypeError, ValueError):
        values["progress"] = analysis.progress
    # result.json is written (atomically) only when the analysis succeeded.
    if state not in ("failed", "cancelled") and result_file.is_file():
        result = Storage.read_json(result_file)
        if result is not None:
            values.update(status="done", progress=1.0, result_path=str(result_file))
            timing = result.get("timing_s")
            values["timings"] = timing if isinstance(timing, dict) else None
            values["mean_error_deg"] = headline_error(result)
    if state == "done" and "result_path" not in values:
        values["status"] = analysis.status  # done without a readable result: wait for it
    if all(getattr(analysis, k) == v for k, v in values.items()):
        return False
    final = values["status"] in TERMINAL_STATES
    now = utcnow()
    stmt = (
        update(Analysis)
        .where(Analysis.id == analysis.id, Analysis.status.not_in(TERMINAL_STATES))
        .values(**values, updated_at=now, **({"notified_at": now} if final else {}))
    )
    # The conditional update makes exactly one reader the owner of the final transition.
    owned = session.execute(stmt).rowcount == 1
    session.commit()
    session.refresh(analysis)
    if owned and final and on_final is not None:
        on_final(analysis)
    return owned


class Notifier:
    """Sends completion webhooks from background threads, retrying with backoff (bounded):
    one delivery per receiver (the club's default ``webhook_url`` and each enabled
    ``WebhookEndpoint`` subscribed to the event).

    Each delivery is checked and pinned to a public address (:mod:`app.core.webhooks`) before
    every attempt, signed with a fresh timestamp, and carries one delivery id for all its
    attempts (``X-Coach-Delivery`` and ``delivery_id`` in the body).
    """

    def __init__(self, settings: Settings, session_factory: sessionmaker) -> None:
        self.settings = settings
        self.session_factory = session_factory
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()

    def __call__(self, analysis: Analysis) -> None:
        """Send the analysis' final state to every receiver of its event: the club's default
        webhook and its endpoints subscribed to the event, each with its own secret and
        delivery id."""
        if analysis.status not in TERMINAL_STATES:  # done, failed, cancelled
            return
        event = f"analysis.{analysis.status}"
        with self.session_factory() as session:
            targets = crud.webhook_targets(session, club_id=analysis.club_id, event=event)
        if not targets:
            return
        public = AnalysisPublic.model_validate(analysis).model_dump(mode="json")
        for url, secret in targets:
            delivery_id = str(uuid.uuid4())
            body = json.dumps(
                {"delivery_id": delivery_id, "event": event, "analysis": public},
                separators=(",", ":"),
            ).encode()
            thread = threading.Thread(
                target=self.deliver,
                args=(url, secret, body, analysis.id, delivery_id),
                daemon=True,
            )
            with self._lock:
                self._threads = [t for t in self._threads if t.is_alive()] + [thread]
            thread.start()

    def deliver(
        self, url: str, secret: str, body: bytes, analysis_id: str, delivery_id: str
    ) -> bool:
        """POST ``body`` to ``url`` until a 2xx answer or the attempts run out; True when it
        was delivered. An internal address, a redirect or a 4xx answer (but 408 and 429)
        ends the delivery at once."""
        s = self.settings
        for attempt in range(s.webhook_attempts):
            try:
                dest = webhooks.destination(url, allow_private=s.webhook_allow_private)
                timestamp = int(time.time())
                headers = {
                    "Content-Type": "application/json",
                    "User-Agent": "motion-coach-webhook/1",
                    "X-Coach-Delivery": delivery_id,
                    "X-Coach-Timestamp": str(timestamp),
                    "X-Coach-Signature": sign_webhook(body, secret, timestamp),
                }
                r = webhooks.post(dest, body, headers, timeout_s=s.webhook_timeout_s)
                if r.status_code < 300:
                    log.info("webhook.delivered analysis=%s attempt=%d", analysis_id, attempt + 1)
                    return True
                if r.status_code < 400:  # a redirect could lead anywhere: not followed
                    log.warning(
                        "webhook.refused analysis=%s status=%d redirect not followed",
                        analysis_id, r.status_code,
                    )  # fmt: skip
                    return False
                if r.status_code < 500 and r.status_code not in (408, 429):
                    log.warning("webhook.refused analysis=%s status=%d", analysis_id, r.status_code)
                    return False
                log.warning("webhook.retry analysis=%s status=%d", analysis_id, r.status_code)
            except webhooks.UnsafeWebhookUrl as exc:
                log.warning("webhook.refused analysis=%s reason=%s", analysis_id, exc)
                return False
            except (webhooks.UnresolvedHost, httpx.HTTPError) as exc:
                log.warning("webhook.retry analysis=%s error=%s", analysis_id, exc)
            if attempt + 1 < s.webhook_attempts:
                time.sleep(s.webhook_backoff_s * 2**attempt)
        log.error("webhook.gave_up analysis=%s attempts=%d", analysis_id, s.webhook_attempts)
        return False

    def wait(self, timeout: float = 10.0) -> None:
        """Join the delivery threads (tests, shutdown)."""
        deadline = time.monotonic() + timeout
        with self._lock:
            threads = list(self._threads)
        for t in threads:
            t.join(max(0.0, deadline - time.monotonic()))


class Reflector:
    """Background thread: reflects every active analysis every ``interval`` seconds, then
    calls ``recover(session)`` (``app.core.recovery.recover``: lost analyses queued again)."""

    def __init__(
        self,
        session_factory: sessionmaker,
        on_final: OnFinal,
        interval: float,
        recover: Callable[[Session], object] | None = None,
    ) -> None:
        self.session_factory = session_factory
        self.on_final = on_final
        self.interval = interval
        self.recover = recover
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="coach-reflector", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            try:
                with self.session_factory() as session:
                    for analysis in crud.list_active_analyses(session):
                        reflect(session, analysis, on_final=self.on_final)
                    if self.recover is not None:
                        self.recover(session)
            except Exception:  # keep reflecting: one bad row or a locked db is not fatal
                log.exception("reflector.error")
