"""Service commands for ``coach``: ``serve`` (and ``worker``, when the worker package has it).

``coach serve`` runs the API with uvicorn. With the default ``broker_url = "embedded"`` it
also starts a local worker (``worker.embedded``), so one command runs everything without
Redis or Docker. On first run it seeds a demo club (idempotent).
"""

from __future__ import annotations

import argparse
import logging
import os
import shutil
from pathlib import Path

log = logging.getLogger("app.serve")

REPO = Path(__file__).resolve().parents[1]
DEMO_BVH = REPO.parent / "shared" / "data" / "cmu" / "64_29.bvh"
DEMO_CLUB = "Demo club"
DEV_KEY_NAME = "development"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("serve", help="run the web app and REST API (and an embedded worker)")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=8000)
    p.add_argument("--data-dir", type=Path, default=None, help="default: $COACH_DATA_DIR or ./data")
    p.add_argument("--no-seed", action="store_true", help="do not create the demo club")
    p.add_argument("--no-worker", action="store_true", help="do not start the embedded worker")
    p.set_defaults(func=run_serve)
    try:
        from worker import commands as worker_commands
    except ImportError:  # the worker package has no command yet
        worker_commands = None
    if worker_commands is not None and hasattr(worker_commands, "register"):
        worker_commands.register(sub)


def seed(session, settings, storage, *, out=print) -> None:
    """The demo club, a coach, a performer, a development key and the demo reference.

    Idempotent: rows are created only when missing. In development a fresh key replaces the
    previous development key on every run (keys are stored hashed and cannot be shown again).
    """
    from app import crud
    from app.core import validation

    club = crud.get_club_by_name(session, DEMO_CLUB)
    if club is None:
        club = crud.create_club(session, name=DEMO_CLUB)
        session.commit()
        log.info("seed.club id=%d", club.id)
    if crud.get_user_by_email(session, club_id=club.id, email="coach@example.com") is None:
        password = "coach-demo-password" if settings.is_development else os.urandom(16).hex()
        crud.create_user(
            session, club_id=club.id, role="coach", email="coach@example.com",
            display_name="Demo coach", password=password,
        )  # fmt: skip
        if settings.is_development:
            out(f"coach: demo coach login: coach@example.com / {password}")
    if crud.get_user_by_email(session, club_id=club.id, email="performer@example.com") is None:
        password = "performer-demo-password" if settings.is_development else None
        crud.create_user(
            session, club_id=club.id, role="performer", email="performer@example.com",
            display_name="Demo performer", password=password,
        )  # fmt: skip
        if password:
            out(f"coach: demo performer login: performer@example.com / {password}")
    if crud.get_reference_by_name(session, club_id=club.id, name="CMU 64_29 (golf swing)") is None:
        if not DEMO_BVH.is_file():
            log.warning("seed.reference_skipped missing=%s", DEMO_BVH)
        else:
            try:
                derived = validation.inspect_reference(DEMO_BVH, None)
                ref = crud.create_reference(session, club_id=club.id, name="CMU 64_29 (golf swing)")
                dest = storage.reference_dir(ref.id) / "reference.bvh"
                dest.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(DEMO_BVH, dest)
                ref.bvh_path, ref.derived = str(dest), derived
                session.commit()
            except Exception as exc:  # a broken demo file must not stop the server
                session.rollback()
                log.warning("seed.reference_failed error=%s", exc)
    if settings.is_development:
        for row in crud.list_api_keys(session, club_id=club.id)[0]:
            if row.name == DEV_KEY_NAME:
                crud.revoke_api_key(session, row)
        _, key = crud.create_api_key(session, club_id=club.id, name=DEV_KEY_NAME)
        out(f"coach: development API key for {DEMO_CLUB!r}: {key}")


DEMO_ANALYSIS_KEY = "demo-analysis"


def seed_demo_analysis(session, settings, storage, queue, *, out=print) -> None:
    """Queue one analysis of a synthetic performer against the demo reference (first run only).

    The video is made by the engine's own generator (engine.synth: a time-warped 64_29 with
    articulation errors in one segment), so the demo shows a real analysis with no upload.
    """
    import uuid

    import numpy as np

    from app import crud
    from app.core.queue import analysis_job
    from app.models import Analysis

    club = crud.get_club_by_name(session, DEMO_CLUB)
    ref = club and crud.get_reference_by_name(
        session, club_id=club.id, name="CMU 64_29 (golf swing)"
    )
    performer = club and crud.get_user_by_email(
        session, club_id=club.id, email="performer@example.com"
    )
    if ref is None or performer is None or not ref.bvh_path:
        return
    if crud.get_analysis_by_idempotency_key(session, club_id=club.id, key=DEMO_ANALYSIS_KEY):
        return
    from worker.contract import AnalysisFolder
    from worker.engine_surface import SynthSettings, load_reference, synthesize, write_video

    analysis_id = str(uuid.uuid4())
    work_dir = storage.analysis_dir(analysis_id)
    work_dir.mkdir(parents=True, exist_ok=True)
    out("coach: making the demo video (synthetic performer, about 10 s)...")
    case = synthesize(
        load_reference(ref.bvh_path),
        settings=SynthSettings(fps=15.0, n_wrong=1, error_deg=25.0, noise_sigma=2.0),
        rng=np.random.default_rng(7),
    )
    video_path = AnalysisFolder(work_dir).video(".mp4")
    write_video(video_path, case.frames, case.fps)
    analysis = Analysis(
        id=analysis_id, club_id=club.id, performer_id=performer.id, reference_id=ref.id,
        video_path=str(video_path), work_dir=str(work_dir), status="queued",
        message=f"queued ({len(case.frames)} frames at {case.fps:.1f} fps)",
        idempotency_key=DEMO_ANALYSIS_KEY,
    )  # fmt: skip
    session.add(analysis)
    session.commit()
    analysis.task_id = queue.enqueue(analysis_job(analysis, ref, settings.engine_preset))
    session.commit()
    out(f"coach: demo analysis queued: /analyses/{analysis_id}")


def resume_unfinished(session, settings, queue, *, purge=None, out=print) -> int:
    """Re-queue analyses left queued or running when the last server stopped.

    The embedded transport loses a message whose worker was killed, so its queue is purged
    and rebuilt from the database; each analysis resumes from its last finished stage (the
    worker skips stages whose output exists).
    """
    from app import crud
    from app.core.queue import analysis_job, purge_embedded_queue
    from app.models import Reference

    (purge or purge_embedded_queue)()
    rows = crud.list_active_analyses(session)
    for analysis in rows:
        reference = session.get(Reference, analysis.reference_id)
        if reference is None:
            continue
        analysis.task_id = queue.enqueue(analysis_job(analysis, reference, settings.engine_preset))
        session.commit()
    if rows:
        out(f"coach: resumed {len(rows)} unfinished analyses")
    return len(rows)


def run_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from app.core.config import Settings, get_settings
    from app.main import create_app

    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s %(message)s")
    if args.data_dir is not None:
        os.environ["COACH_DATA_DIR"] = str(args.data_dir.resolve())
        get_settings.cache_clear()
    settings: Settings = get_settings()
    # The worker (embedded or not) reads the same environment.
    os.environ.setdefault("COACH_DATA_DIR", str(settings.data_dir.resolve()))
    app = create_app(settings)
    if not args.no_seed:
        with app.state.sessionmaker() as session:
            seed(session, settings, app.state.storage)

    embedded = None
    if settings.broker_url == "embedded" and not args.no_worker:
        try:
            import worker.embedded as embedded
        except ImportError:
            embedded = None
        if embedded is not None and hasattr(embedded, "start"):
            from app.core.queue import get_queue

            with app.state.sessionmaker() as session:
                resume_unfinished(session, settings, get_queue())
                if not args.no_seed:
                    seed_demo_analysis(session, settings, app.state.storage, get_queue())
            embedded.start(settings.data_dir.resolve(), settings.worker_concurrency)
        else:
            embedded = None
            log.warning("serve.no_embedded_worker: analyses stay queued until a worker runs")
    print(f"coach: open http://{args.host}:{args.port}/ (Ctrl+C to stop)", flush=True)
    try:
        uvicorn.run(app, host=args.host, port=args.port, log_level="info")
    finally:
        if embedded is not None and hasattr(embedded, "stop"):
            embedded.stop()
    return 0
