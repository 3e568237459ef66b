import json
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, File, Form, Request, Response, UploadFile
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse

from app import crud
from app.api.access import reference_for
from app.api.deps import (
    CREATED,
    CurrentCoach,
    CurrentPrincipal,
    PageDep,
    SessionDep,
    SettingsDep,
    StorageDep,
    location,
)
from app.api.errors import ApiError, errors
from app.api.params import DbId
from app.core import media, validation
from app.core.storage import Storage, UploadTooLarge
from app.schemas import DomainUpdate, ReferencePublic, ReferencesPublic
from worker.engine_surface import InvalidInput

router = APIRouter(prefix="/references", tags=["references"], responses=errors(401, 429))


def too_large(what: str, limit: int) -> ApiError:
    return ApiError(
        413, "too_large", f"the {what} is larger than the limit of {limit} bytes",
        {"limit_bytes": limit},
    )  # fmt: skip


@router.post(
    "",
    status_code=201,
    response_model=ReferencePublic,
    summary="Upload a reference motion (BVH) with an optional domain configuration (JSON)",
    description=(
        "The BVH is imported onto the 17-joint body before it is accepted; a file whose "
        "skeleton cannot be mapped is refused with 422 naming the missing joints. The optional "
        "domain JSON may hold `mapping` (our joint -> BVH joint), `units_to_m`, `segments` "
        "(the reference frames where the segments start; without it they are detected) and "
        "the engine's domain keys (`segment_names`, `bone_weights`, `tolerances_deg`, "
        "`default_tolerance_deg`, `boundary`). `derived.segments` gives the segment "
        "boundaries every analysis uses: the starts, then the last frame. Starts outside the "
        "motion, or names that do not match the number of segments, are refused with 422 "
        "`invalid_domain`. A file with more frames, joints or a longer duration than the "
        "service's limits (`COACH_MAX_REFERENCE_FRAMES`, `_JOINTS`, `_DURATION_S`) is refused "
        "with 422 `invalid_reference` as soon as its header shows it. 201 with the "
        "reference's `Location`."
    ),
    responses=CREATED | errors(413, 422),
)
async def create_reference(
    request: Request,
    response: Response,
    who: CurrentCoach,
    session: SessionDep,
    settings: SettingsDep,
    storage: StorageDep,
    file: Annotated[UploadFile, File(description="The BVH file.")],
    name: Annotated[str | None, Form(min_length=1, max_length=200)] = None,
    domain: Annotated[UploadFile | None, File(description="Domain configuration JSON.")] = None,
):
    tmp = storage.new_tmp_dir()
    try:
        bvh = tmp / "reference.bvh"
        try:
            await storage.receive(file, bvh, settings.max_bvh_bytes)
        except UploadTooLarge as exc:
            raise too_large("BVH file", exc.limit) from None
        domain_config = None
        if domain is not None:
            raw = await domain.read(settings.max_domain_bytes + 1)
            if len(raw) > settings.max_domain_bytes:
                raise too_large("domain configuration", settings.max_domain_bytes)
            try:
                domain_config = validation.parse_domain(raw)
            except InvalidInput as exc:
                raise ApiError(422, "invalid_domain", str(exc)) from None
        # Import and segment detection take up to ~10 s on the longest accepted file, so
        # they run in a worker thread, off the event loop. Memory is bounded by the limits:
        # a file over max_reference_frames/joints/duration_s is refused as it is read, before
        # any frame is stored; an accepted one holds frames x channels values (under 4 x its
        # max_bvh_bytes) and its kinematics run in ~25 MB chunks (about 150 MB at worst).
        try:
            derived = await run_in_threadpool(
                validation.inspect_reference, bvh, domain_config, settings
            )
        except validation.InvalidDomain as exc:
            raise ApiError(422, "invalid_domain", str(exc)) from None
        except InvalidInput as exc:
            raise ApiError(422, "invalid_reference", str(exc)) from None
        label = name or (Path(file.filename or "").stem[:200] or "reference")
        ref = add_reference(session, who, storage, label, bvh, domain_config, derived)
        response.headers["Location"] = location(request, "read_reference", reference_id=ref.id)
        return ref
    finally:
        Storage.remove(tmp)


def add_reference(session, who, storage: Storage, label: str, bvh: Path, domain_config, derived):
    """Record an accepted reference and move its files (``bvh`` and, for one built from
    takes, the ``takes.png`` beside it) into its folder; nothing is left of it on failure."""
    final_dir: Path | None = None
    try:
        ref = crud.create_reference(session, club_id=who.club.id, name=label)
        final_dir = storage.reference_dir(ref.id)
        ref.bvh_path = str(Storage.move(bvh, final_dir / "reference.bvh"))
        if (bvh.parent / "takes.png").exists():
            Storage.move(bvh.parent / "takes.png", final_dir / "takes.png")
        ref.domain_config = domain_config
        ref.derived = derived
        session.commit()
        return ref
    except BaseException:
        session.rollback()
        Storage.remove(final_dir)
        raise


@router.post(
    "/takes",
    status_code=201,
    response_model=ReferencePublic,
    summary="Build a reference from several takes of one action (seed 002)",
    description=(
        "Two or more BVH takes of one action (`takes`, one file each) are synchronised to "
        "their median take; the reference is their mean performance, on the median take's "
        "frames, and its domain keeps the expert's spread of every bone at every frame "
        "(`variation`), so that every analysis against it also says whether an error lies "
        "within the expert's own take-to-take variation. A take far from the others (another "
        "action, a failed capture) is left out and named in `derived.takes.warnings`; fewer "
        "than two takes of one action left, a file that is not a mappable BVH or over the "
        "limits, or more than `COACH_MAX_REFERENCE_TAKES` takes are refused with 422 "
        "`invalid_reference`. `thumbnail`, `strip` and `takes.png` show the result."
    ),
    responses=CREATED | errors(413, 422),
)
async def create_reference_from_takes(
    request: Request,
    response: Response,
    who: CurrentCoach,
    session: SessionDep,
    settings: SettingsDep,
    storage: StorageDep,
    takes: Annotated[
        list[UploadFile],
        File(description="Two or more BVH takes of one action.", json_schema_extra={"minItems": 2}),
    ],
    name: Annotated[str | None, Form(min_length=1, max_length=200)] = None,
    sport: Annotated[str, Form(max_length=40)] = "",
):
    if not 2 <= len(takes) <= settings.max_reference_takes:
        raise ApiError(
            422, "invalid_reference",
            f"give 2 to {settings.max_reference_takes} takes of one action, got {len(takes)}",
        )  # fmt: skip
    tmp = storage.new_tmp_dir()
    try:
        paths = []
        for i, f in enumerate(takes):
            paths.append(tmp / f"take_{i}.bvh")
            try:
                await storage.receive(f, paths[-1], settings.max_bvh_bytes)
            except UploadTooLarge as exc:
                raise too_large(f"take {i + 1}", exc.limit) from None
        names = [Path(f.filename or "").stem[:60] or f"take {i + 1}" for i, f in enumerate(takes)]
        # Reading, synchronising every pair and the plot take 1-5 s: off the event loop.
        try:
            domain_config, derived = await run_in_threadpool(
                validation.build_from_takes, paths, names, tmp, settings, sport
            )
        except InvalidInput as exc:
            raise ApiError(422, "invalid_reference", str(exc)) from None
        label = name or ("takes " + ", ".join(derived["takes"]["kept"]))[:200]
        bvh = tmp / "reference.bvh"
        ref = add_reference(session, who, storage, label, bvh, domain_config, derived)
        response.headers["Location"] = location(request, "read_reference", reference_id=ref.id)
        return ref
    finally:
        Storage.remove(tmp)


@router.get(
    "/{reference_id}/takes.png",
    summary="A reference built from takes: the takes before and after synchronisation",
    responses={200: {"content": {"image/png": {}}}} | errors(404),
)  # fmt: skip
def reference_takes_plot(reference_id: DbId, who: CurrentPrincipal, session: SessionDep):
    ref = reference_for(session, who, reference_id)
    path = Path(ref.bvh_path).with_name("takes.png")
    if not path.is_file():
        raise ApiError(404, "not_found", f"reference {reference_id} was not built from takes")
    return Response(path.read_bytes(), media_type="image/png", headers=_PICTURE_HEADERS)


@router.get("", response_model=ReferencesPublic, summary="The club's references")
def list_references(who: CurrentPrincipal, session: SessionDep, page: PageDep):
    items, total = crud.list_references(
        session, club_id=who.club.id, limit=page.limit, offset=page.offset
    )
    return ReferencesPublic(
        items=[ReferencePublic.model_validate(r) for r in items], total=total,
        limit=page.limit, offset=page.offset,
    )  # fmt: skip


# ``:int``: ``/references/takes`` is the POST route above, so GET or DELETE there answers
# 405 (Allow: POST) rather than "reference_id is not an integer".
@router.get(
    "/{reference_id:int}", response_model=ReferencePublic, summary="One reference",
    responses=errors(404),
)  # fmt: skip
def read_reference(reference_id: DbId, who: CurrentPrincipal, session: SessionDep):
    return reference_for(session, who, reference_id)


@router.put(
    "/{reference_id}/domain", response_model=ReferencePublic,
    summary="Set the coach's segment names, bone weights and tolerances (and the name)",
    responses=errors(403, 404, 422),
)  # fmt: skip
def update_domain(
    reference_id: DbId, body: DomainUpdate, who: CurrentCoach, session: SessionDep
):  # fmt: skip
    ref = reference_for(session, who, reference_id)
    config = dict(ref.domain_config or {})
    config.update(
        segment_names=[s.strip() for s in body.segment_names],
        bone_weights=body.bone_weights,
        tolerances_deg=body.tolerances_deg,
        default_tolerance_deg=body.default_tolerance_deg,
        key_position_names=[s.strip() for s in body.key_position_names],
    )
    if body.segments:
        config["segments"] = sorted(set(body.segments))
    elif body.segments is not None:  # [] : the boundaries detected from the motion again
        config.pop("segments", None)
    try:
        config = validation.parse_domain(json.dumps(config).encode())
    except InvalidInput as exc:
        raise ApiError(422, "invalid_domain", str(exc)) from None
    derived = dict(ref.derived or {})
    if body.segments is not None:  # the boundaries move: the motion says where they may go
        try:
            found = validation.inspect_reference(Path(ref.bvh_path), config)
        except InvalidInput as exc:
            raise ApiError(422, "invalid_domain", str(exc)) from None
        derived["segments"] = found["segments"]
    n = len(derived.get("segments") or []) - 1  # boundaries: n + 1 frames
    if config["segment_names"] and n > 0 and len(config["segment_names"]) != n:
        raise ApiError(
            422, "invalid_domain",
            f"the reference has {n} segments, got {len(config['segment_names'])} names",
        )  # fmt: skip
    keys = config["key_position_names"]
    if keys and n > 0 and len(keys) != n + 1:
        raise ApiError(
            422, "invalid_domain",
            f"the reference's {n} segments have {n + 1} key positions (each start, then the "
            f"end), got {len(keys)} names",
        )  # fmt: skip
    ref.domain_config, ref.derived = config, derived
    if body.name:
        ref.name = body.name
    session.commit()
    return ref


_PICTURE_HEADERS = {"Cache-Control": "private, max-age=300"}


@router.get(
    "/{reference_id}/thumbnail.svg", summary="The first posture, drawn",
    responses={200: {"content": {"image/svg+xml": {}}}} | errors(404),
)  # fmt: skip
async def reference_thumbnail(reference_id: DbId, who: CurrentPrincipal, session: SessionDep):
    ref = reference_for(session, who, reference_id)
    first = int((ref.derived or {}).get("first_motion_frame") or 0)
    svg = await run_in_threadpool(media.reference_thumbnail, ref.bvh_path, first)
    return Response(svg, media_type="image/svg+xml", headers=_PICTURE_HEADERS)


@router.get(
    "/{reference_id}/strip.svg", summary="One posture per segment, drawn",
    responses={200: {"content": {"image/svg+xml": {}}}} | errors(404),
)  # fmt: skip
async def reference_strip(reference_id: DbId, who: CurrentPrincipal, session: SessionDep):
    ref = reference_for(session, who, reference_id)
    derived = ref.derived or {}
    svg = await run_in_threadpool(
        media.reference_strip, ref.bvh_path, list(derived.get("segments") or []),
        int(derived.get("first_motion_frame") or 0),
    )  # fmt: skip
    return Response(svg, media_type="image/svg+xml", headers=_PICTURE_HEADERS)


@router.get(
    "/{reference_id}/preview.json",
    summary="Sampled postures (front and side view) for a looping preview",
    responses=errors(404),
)
async def reference_preview(reference_id: DbId, who: CurrentPrincipal, session: SessionDep):
    ref = reference_for(session, who, reference_id)
    derived = ref.derived or {}
    data = await run_in_threadpool(
        media.reference_preview, ref.bvh_path, int(derived.get("first_motion_frame") or 0),
        fps=float(derived.get("fps") or 0.0),
    )  # fmt: skip
    return JSONResponse(data, headers=_PICTURE_HEADERS)


@router.get(
    "/{reference_id}/motion.json",
    summary="The expert's hand speed per frame and the segment boundaries, to edit them",
    description="`speed_m_per_frame`: the wrists' mean speed relative to the hip, averaged "
    "over `step` frames per point; `segments`: each segment's first frame, then the last "
    "frame. Set new starts with `PUT /domain` (`segments`).",
    responses=errors(404),
)
async def reference_motion(reference_id: DbId, who: CurrentPrincipal, session: SessionDep):
    ref = reference_for(session, who, reference_id)
    derived = ref.derived or {}
    first = int(derived.get("first_motion_frame") or 0)
    data = await run_in_threadpool(media.reference_motion_curve, ref.bvh_path, first)
    data |= {"fps": float(derived.get("fps") or 0.0), "first_motion_frame": first,
             "segments": list(derived.get("segments") or [])}  # fmt: skip
    return JSONResponse(data)  # not cached: the boundaries change with PUT /domain


@router.delete(
    "/{reference_id:int}", status_code=204, summary="Delete a reference no analysis uses",
    responses=errors(403, 404, 409),
)  # fmt: skip
def delete_reference(
    reference_id: DbId, who: CurrentCoach, session: SessionDep, storage: StorageDep
) -> Response:
    ref = reference_for(session, who, reference_id)
    if crud.reference_in_use(session, ref):
        raise ApiError(
            409, "conflict", f"reference {reference_id} is used by analyses; delete them first"
        )
    session.delete(ref)
    session.commit()
    Storage.remove(storage.reference_dir(reference_id))
    return Response(status_code=204)
