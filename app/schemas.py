"""Request and response bodies, one schema per role (``XCreate``, ``XUpdate``, ``XPublic``).

Every string has a length limit and every list a size limit: nothing unbounded comes in.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Generic, Literal, TypeVar, get_args

from pydantic import (
    AnyHttpUrl,
    BaseModel,
    ConfigDict,
    Field,
    TypeAdapter,
    ValidationError,
    field_validator,
    model_validator,
)

from app.core.validation import engine_domain
from app.models import segment_names

#: Neither "@" nor a space. ``\s`` differs between the server's regex engines and the
#: document's (ECMA) on U+001C-U+001F, U+0085 and U+FEFF: naming them makes both agree.
_NOT_AT_OR_SPACE = r"[^@\s\x1c-\x1f\x85\ufeff]"
# A plausibility check only (no DNS, no email-validator dependency).
EMAIL_PATTERN = rf"^{_NOT_AT_OR_SPACE}+@{_NOT_AT_OR_SPACE}+\.{_NOT_AT_OR_SPACE}+$"

AnalysisState = Literal["queued", "running", "done", "failed", "cancelled"]

_HTTP_URL = TypeAdapter(AnyHttpUrl)

#: The JSON schema of a webhook URL (its host's addresses are checked by the route).
_WEBHOOK_URL_SCHEMA = {
    "type": "string", "format": "uri", "maxLength": 2000,
    "pattern": "^[hH][tT][tT][pP][sS]?://[^/?#]+",
}  # fmt: skip

#: ``app.models.WEBHOOK_EVENTS`` spelled out, so the OpenAPI document lists them.
WebhookEvent = Literal["analysis.done", "analysis.failed", "analysis.cancelled"]


def _http_url(v: str, *, removable: bool) -> str:
    """An http(s) URL normalised (``HTTP://Example.COM`` -> ``http://example.com/``)."""
    try:
        return str(_HTTP_URL.validate_python(v))
    except ValidationError:
        remove = ', or "" to remove the webhook' if removable else ""
        raise ValueError(f"must be an http or https URL{remove}") from None


def _unique_events(events: list[WebhookEvent]) -> list[WebhookEvent]:
    """``events`` without repeats, in the order of ``WEBHOOK_EVENTS``."""
    return [e for e in get_args(WebhookEvent) if e in events]


class _Orm(BaseModel):
    model_config = ConfigDict(from_attributes=True)


# ---- errors (the one error shape of the API)
class ErrorBody(BaseModel):
    code: str
    message: str
    details: dict[str, Any] = {}


class ErrorResponse(BaseModel):
    error: ErrorBody


# ---- health
class HealthPublic(BaseModel):
    status: Literal["ok"] = "ok"
    version: str
    database: Literal["ok", "error"]


# ---- club
class ClubPublic(_Orm):
    id: int
    name: str
    webhook_url: str | None
    created_at: datetime


class ClubUpdate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str | None = Field(default=None, min_length=1, max_length=200)
    #: An http(s) URL, or "" to remove the webhook. Whether its host is a public address is
    #: checked by the route (app.core.webhooks), which knows the service's settings.
    webhook_url: str | None = Field(
        default=None,
        max_length=2000,
        description='An http or https URL on a public address, or "" to remove the webhook.',
        json_schema_extra={
            "anyOf": [_WEBHOOK_URL_SCHEMA, {"type": "string", "maxLength": 0}, {"type": "null"}]
        },
    )
    rotate_webhook_secret: bool = Field(default=False, strict=True)  # JSON true or false

    @field_validator("webhook_url")
    @classmethod
    def _http_url(cls, v: str | None) -> str | None:
        return _http_url(v, removable=True) if v else v


class ClubUpdated(ClubPublic):
    #: Shown only when a new secret was generated (first webhook URL or rotation).
    webhook_secret: str | None = None


# ---- webhook endpoints (more receivers than the club's default webhook_url)
class WebhookEndpointCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    url: str = Field(
        max_length=2000,
        description="An http or https URL on a public address.",
        json_schema_extra=_WEBHOOK_URL_SCHEMA,
    )
    #: Repeats are dropped; the order is WEBHOOK_EVENTS'.
    events: list[WebhookEvent] = Field(
        default=list(get_args(WebhookEvent)),
        min_length=1,
        max_length=3,
        description="The events this endpoint receives (default: all).",
    )
    description: str = Field(default="", max_length=200)

    @field_validator("url")
    @classmethod
    def _url(cls, v: str) -> str:
        return _http_url(v, removable=False)

    @field_validator("events")
    @classmethod
    def _events(cls, v: list[WebhookEvent]) -> list[WebhookEvent]:
        return _unique_events(v)


class WebhookEndpointUpdate(BaseModel):
    """Fields left out (or null) stay as they are."""

    model_config = ConfigDict(extra="forbid")

    url: str | None = Field(
        default=None,
        max_length=2000,
        description="An http or https URL on a public address.",
        json_schema_extra={"anyOf": [_WEBHOOK_URL_SCHEMA, {"type": "null"}]},
    )
    events: list[WebhookEvent] | None = Field(default=None, min_length=1, max_length=3)
    description: str | None = Field(default=None, max_length=200)
    #: A new signing secret, shown once in the answer; the old one stops signing at once.
    rotate_secret: bool = Field(default=False, strict=True)
    #: false pauses deliveries to this endpoint, true resumes them.
    enabled: bool | None = Field(default=None, strict=True)

    @field_validator("url")
    @classmethod
    def _url(cls, v: str | None) -> str | None:
        return v if v is None else _http_url(v, removable=False)

    @field_validator("events")
    @classmethod
    def _events(cls, v: list[WebhookEvent] | None) -> list[WebhookEvent] | None:
        return v if v is None else _unique_events(v)


class WebhookEndpointPublic(_Orm):
    id: int
    url: str
    events: list[WebhookEvent]
    description: str
    created_at: datetime
    #: Set while deliveries to it are paused.
    disabled_at: datetime | None


class WebhookEndpointCreated(WebhookEndpointPublic):
    #: The signing secret; shown once, never again.
    secret: str


class WebhookEndpointUpdated(WebhookEndpointPublic):
    #: The new signing secret when ``rotate_secret`` was true (shown once), else null.
    secret: str | None = None


# ---- API keys
class ApiKeyCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str = Field(default="", max_length=100)


class ApiKeyPublic(_Orm):
    id: int
    name: str
    prefix: str
    created_at: datetime
    last_used_at: datetime | None
    revoked_at: datetime | None


class ApiKeyCreated(ApiKeyPublic):
    #: The whole key; shown once, never again.
    key: str


# ---- users
class PerformerCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    email: str = Field(max_length=320, pattern=EMAIL_PATTERN)
    display_name: str = Field(min_length=1, max_length=200)
    password: str | None = Field(default=None, min_length=8, max_length=256)


class UserPublic(_Orm):
    id: int
    role: Literal["coach", "performer"]
    email: str
    display_name: str
    created_at: datetime


class LoginRequest(BaseModel):
    email: str = Field(max_length=320, pattern=EMAIL_PATTERN)
    password: str = Field(min_length=1, max_length=256)


class PasswordChange(BaseModel):
    current_password: str = Field(min_length=1, max_length=256)
    new_password: str = Field(min_length=8, max_length=256)


# ---- references
class ReferencePublic(_Orm):
    """A reference as stored, plus what pages show of it (derived from the stored fields)."""

    id: int
    name: str
    domain_config: dict[str, Any] | None
    derived: dict[str, Any]
    created_at: datetime
    frames: int | None = None
    fps: float | None = None
    duration_s: float | None = None
    #: One name per segment ("segment i" where the coach named none); empty when none named
    #: and none derived.
    segment_names: list[str] = []
    #: The engine's part of ``domain_config`` (without the BVH import options).
    domain: dict[str, Any] = {}
    thumbnail: str = ""
    strip: str = ""
    preview: str = ""
    #: A reference built from several takes: their synchronisation plot (else empty). Its
    #: ``derived.takes`` names the takes kept, the median take, the warnings and the
    #: expert's spread per bone; ``domain_config.variation`` says how many frames it covers.
    takes_plot: str = ""

    @model_validator(mode="after")
    def _derive(self) -> ReferencePublic:
        config, derived = self.domain_config or {}, self.derived or {}
        self.frames, self.fps = derived.get("frames"), derived.get("fps")
        self.duration_s = derived.get("duration_s")
        n = max(len(derived.get("segments") or []) - 1, 0) or len(
            config.get("segment_names") or []
        )
        self.segment_names = segment_names(config, n)
        if isinstance(config.get("variation"), dict):  # thousands of numbers: summarised
            variation = dict(config["variation"])
            rows = variation.pop("bone_sd_deg", None)
            variation["frames"] = len(rows) if isinstance(rows, list) else 0
            config = {**config, "variation": variation}
            self.domain_config = config
        self.domain = engine_domain(config)
        base = f"/api/v1/references/{self.id}"
        self.thumbnail, self.strip = f"{base}/thumbnail.svg", f"{base}/strip.svg"
        self.preview = f"{base}/preview.json"
        self.takes_plot = f"{base}/takes.png" if "takes" in derived else ""
        return self


class DomainUpdate(BaseModel):
    """The coach-editable part of a reference's domain (engine.reference.domain)."""

    name: str | None = Field(default=None, min_length=1, max_length=200)
    segment_names: list[Annotated[str, Field(max_length=100)]] = Field(default=[], max_length=64)
    bone_weights: dict[str, float] = Field(default={}, max_length=32)
    tolerances_deg: dict[str, float] = Field(default={}, max_length=32)
    default_tolerance_deg: float = Field(default=0.0, ge=0, le=180)
    #: The moments between segments, by name: each segment's start, then the last one's end
    #: (empty: named after the segments).
    key_position_names: list[Annotated[str, Field(min_length=1, max_length=100)]] = Field(
        default=[], max_length=65
    )
    #: The segments' first frames (reference frames, the first the motion's start); None
    #: keeps the present boundaries, [] goes back to the detected ones.
    segments: list[Annotated[int, Field(ge=0, le=10_000_000)]] | None = Field(
        default=None, max_length=65
    )


# ---- analyses
class AnalysisPublic(_Orm):
    id: str
    performer_id: int
    reference_id: int
    status: AnalysisState
    stage: str
    progress: float
    message: str
    error: str | None
    timings: dict[str, Any] | None
    #: The video frames analysed, start..end-1, when the analysis covers one repetition the
    #: user picked (``POST /analyses/{id}/repetitions/{n}``); null for the whole video.
    frames_start: int | None = None
    frames_end: int | None = None
    #: The headline once done: the mean posture error over the frames, in degrees.
    mean_error_deg: float | None = None
    #: What the video's first frame says about the filming, one sentence each, once stages
    #: 0-2 are done (null before): shown while the rest of the analysis runs.
    warnings: list[str] | None = None
    #: When a coach marked the analysis reviewed (null: still to review), and who.
    reviewed_at: datetime | None = None
    reviewed_by_id: int | None = None
    created_at: datetime
    updated_at: datetime


T = TypeVar("T")


class ListPage(BaseModel, Generic[T]):
    """Every list the API returns: one page of ``items`` (``limit`` from ``offset``) of
    ``total`` rows."""

    items: list[T]
    total: int
    limit: int
    offset: int


class AnalysesPublic(ListPage[AnalysisPublic]):
    pass


# ---- captures
class CaptureQuestion(BaseModel):
    """A depth the capture could not settle from the video (or the body's facing)."""

    id: str
    segment: str
    frames: list[int]
    chosen: str
    margin: float
    text: str


class CapturePublic(_Orm):
    id: str
    performer_id: int
    name: str
    height_m: float
    status: AnalysisState
    progress: float
    message: str
    error: str | None
    answers: dict[str, int] | None
    reference_id: int | None
    created_at: datetime
    updated_at: datetime
    #: Once done: frames, fps, the questions left (answer them with ``POST .../answers``).
    frames: int | None = None
    fps: float | None = None
    questions: list[CaptureQuestion] = []


class CapturesPublic(ListPage[CapturePublic]):
    pass


class CaptureAnswers(BaseModel):
    """Answers to a capture's questions: question id -> ``towards`` or ``away`` (``yes`` or
    ``no`` for the facing question)."""

    model_config = ConfigDict(extra="forbid")
    answers: dict[str, Literal["towards", "away", "yes", "no"]] = Field(max_length=200)


class CaptureToReference(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str | None = Field(default=None, min_length=1, max_length=200)


class SegmentPublic(BaseModel):
    index: int
    reference_start: int
    reference_end: int
    performer_start: int
    performer_end: int
    #: Performer duration / reference duration (> 1: slower than the expert).
    tempo_ratio: float | None
    mean_error_deg: float
    worst_bone: str | None
    worst_bone_error_deg: float | None
    bone_mean_errors_deg: dict[str, float]
    #: Frames of the segment whose reported posture the video does not confirm (flag
    #: ``image_misfit``): the errors there may be underestimated.
    misfit_frames: int = 0
    #: Where those frames disagree most: up to two bones whose picture differs most between
    #: the reported posture and the candidate that fits the video best.
    misfit_bones: list[str] = []
    #: Per bone, the mean width (deg) of its error's range over the candidates the video
    #: cannot tell from the reported posture: wide for a bend in depth one camera cannot
    #: measure, narrow for an in-plane one. Empty for results that predate it.
    bone_uncertainty_deg: dict[str, float] = {}
    #: Against a reference built from several takes: whether every bone's mean error lies
    #: within ``z_limit`` times the expert's own spread there (None for a single-take
    #: reference), and the bones that do not, worst first.
    within_expert_range: bool | None = None
    outside_bones: list[str] = []
    #: Per bone, mean error over the expert's mean spread in the segment (z).
    bone_mean_z: dict[str, float] = {}


class SegmentsPublic(BaseModel):
    analysis_id: str
    segments: list[SegmentPublic]


# ---- comments
#: One point of a drawing: shares of the video's width and height, in [0, 1].
Share = Annotated[float, Field(ge=0.0, le=1.0)]
#: One stroke: 2 to 2000 points.
Stroke = Annotated[list[tuple[Share, Share]], Field(min_length=2, max_length=2000)]


class CommentCreate(BaseModel):
    body: str = Field(min_length=1, max_length=4000)
    frame: int | None = Field(default=None, ge=0, le=1_000_000)
    segment: int | None = Field(default=None, ge=0, le=1000)
    #: Strokes drawn over the frame the comment is pinned to (``frame`` required).
    drawing: list[Stroke] | None = Field(default=None, min_length=1, max_length=50)


class CommentPublic(BaseModel):
    id: int
    body: str
    frame: int | None
    segment: int | None
    drawing: list[list[tuple[float, float]]] | None = None
    author: str
    author_id: int | None
    created_at: str


# ---- invites
class InviteCreate(BaseModel):
    display_name: str = Field(default="", max_length=200)
    days: int = Field(default=7, ge=1, le=30)


class InvitePublic(BaseModel):
    url: str
    path: str
    display_name: str
    expires_at: datetime


class JoinBody(BaseModel):
    display_name: str = Field(min_length=1, max_length=200)
    email: str = Field(min_length=3, max_length=320)
    password: str = Field(min_length=1, max_length=1000)


class JoinedPublic(BaseModel):
    id: int
    display_name: str
    url: str


class ApiKeysPublic(ListPage[ApiKeyPublic]):
    pass


class WebhookEndpointsPublic(ListPage[WebhookEndpointPublic]):
    pass


class UsersPublic(ListPage[UserPublic]):
    pass


class ReferencesPublic(ListPage[ReferencePublic]):
    pass


class CommentsPublic(ListPage[CommentPublic]):
    pass
