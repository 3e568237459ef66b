from app import crud
from app.commands import DEMO_CLUB, seed
from app.models import ApiKey, Club, Reference, User


def test_seed_is_idempotent_and_prints_a_working_dev_key(app, client):
    printed = []
    for _ in range(2):
        with app.state.sessionmaker() as s:
            seed(s, app.state.settings, app.state.storage, out=printed.append)
    with app.state.sessionmaker() as s:
        assert s.query(Club).filter_by(name=DEMO_CLUB).count() == 1
        assert s.query(User).count() == 2
        assert s.query(Reference).count() <= 1
        active = [k for k in s.query(ApiKey) if k.revoked_at is None]
        assert len(active) == 1
        key = [line for line in printed if "API key" in line][-1].rsplit(" ", 1)[1]
        assert crud.get_active_api_key(s, key) is not None
    assert client.get("/api/v1/performers", headers={"X-API-Key": key}).status_code == 200


def test_demo_analysis_is_queued_once_with_a_real_video(app, queue, bvh_file):
    import cv2

    from app.commands import seed_demo_analysis
    from app.models import Analysis

    printed: list[str] = []
    with app.state.sessionmaker() as s:
        seed(s, app.state.settings, app.state.storage, out=printed.append)
        for _ in range(2):
            seed_demo_analysis(s, app.state.settings, app.state.storage, queue, out=printed.append)
        rows = s.query(Analysis).all()
    assert len(rows) == 1 and len(queue.jobs) == 1
    assert queue.jobs[0].analysis_id == rows[0].id
    cap = cv2.VideoCapture(rows[0].video_path)
    assert cap.isOpened() and cap.get(cv2.CAP_PROP_FRAME_COUNT) > 20
    assert any("/analyses/" + rows[0].id in line for line in printed)


def test_unfinished_analyses_are_requeued_at_start(app, client, club_ref, queue, video_file):
    from app.commands import resume_unfinished
    from tests.app.conftest import upload

    queued = upload(client, club_ref, video_file).json()["id"]
    done = upload(client, club_ref, video_file).json()["id"]
    with app.state.sessionmaker() as s:
        from app.models import Analysis

        s.get(Analysis, done).status = "done"
        s.commit()
        before = len(queue.jobs)
        purged = []
        n = resume_unfinished(
            s, app.state.settings, queue, purge=lambda: purged.append(1), out=lambda m: None
        )
        assert n == 1 and purged == [1]
    assert [j.analysis_id for j in queue.jobs[before:]] == [queued]
