"""The OpenAPI document is the contract clubs build on: Schemathesis generates requests from
it for every operation and checks every answer against it (issue 26 "Must show").

Bounded to 20 examples per operation so it stays a test (~20 s); any server error, any
status, header or body the document does not declare, and any request the document says is
invalid but the server accepts, fails it.
"""

from __future__ import annotations

import atexit
import shutil
import tempfile
from pathlib import Path

import schemathesis
from hypothesis import HealthCheck, Phase, settings
from schemathesis.specs.openapi.checks import positive_data_acceptance

from app import crud
from app.core.config import Settings
from app.main import create_app


def _fuzz_app():
    """An app in a throw-away data dir with one club, its key and a performer (built at
    import: Schemathesis' fixture loader does not work with this pytest)."""
    data = Path(tempfile.mkdtemp(prefix="coach-fuzz-"))
    atexit.register(shutil.rmtree, data, ignore_errors=True)
    app = create_app(
        Settings(data_dir=data, reflect_interval_s=0, rate_limit_per_s=1e6, rate_limit_burst=10**6)
    )
    with app.state.sessionmaker() as session:
        club = crud.create_club(session, name="fuzz")
        session.commit()
        _, key = crud.create_api_key(session, club_id=club.id, name="fuzz")
        crud.create_user(
            session, club_id=club.id, role="performer", email="p@fuzz.org", display_name="P"
        )
    return app, key


APP, KEY = _fuzz_app()
#: Operations that set a webhook URL.
WEBHOOK_URL_SETTERS = {
    ("PATCH", "/api/v1/club"),
    ("POST", "/api/v1/webhooks"),
    ("PATCH", "/api/v1/webhooks/{webhook_id}"),
}
#: Operations that take a file whose content (a BVH, a video) is checked beyond what the
#: document can say: a generated file is refused with 422 and a reason, as it should be.
FILE_UPLOADS = {
    ("POST", "/api/v1/references"),
    ("POST", "/api/v1/references/takes"),
    ("POST", "/api/v1/analyses"),
    ("POST", "/api/v1/captures"),
    ("POST", "/api/v1/framing"),
}
schema = schemathesis.openapi.from_asgi("/api/v1/openapi.json", APP)


@schema.parametrize()
@settings(
    max_examples=20, deadline=None, derandomize=True, database=None,
    suppress_health_check=list(HealthCheck), phases=[Phase.explicit, Phase.generate],
)  # fmt: skip
def test_every_operation_keeps_to_the_openapi_document(case):
    excluded = []
    if (case.method, case.path) in WEBHOOK_URL_SETTERS | FILE_UPLOADS:
        # A webhook URL's host must resolve when it is set (test_webhook_ssrf.py); the
        # generated hosts never do, and CI has no DNS: the document cannot say so. Nor can
        # it say what makes a file a BVH or a video. Every other check still applies.
        excluded.append(positive_data_acceptance)
    case.call_and_validate(headers={"X-API-Key": KEY}, excluded_checks=excluded)
