import json
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, File, Form, Response, UploadFile
from fastapi.concurrency import run_in_threadpool

from app import crud
from app.api.deps import CurrentClub, PageDep, SessionDep, SettingsDep, StorageDep
from app.api.errors import ApiError, errors, not_found
from app.core import validation
from app.core.storage import Storage, UploadTooLarge
from app.schemas import ReferencePublic
from engine.errors import InvalidInput

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
        "`invalid_domain`."
    ),
    responses=errors(413, 422),
)
async def create_reference(
    club: CurrentClub,
    session: SessionDep,
    settings: SettingsDep,
    storage: StorageDep,
    file: Annotated[UploadFile, File(description="The BVH file.")],
    name: Annotated[str | None, Form(min_length=1, max_length=200)] = None,
    domain: Annotated[UploadFile | None, File(description="Domain configuration JSON.")] = None,
):
    tmp = storage.new_tmp_dir()
    final_dir: Path | None = None
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
        try:
            derived = await run_in_threadpool(validation.inspect_reference, bvh, domain_config)
        except validation.InvalidDomain as exc:
            raise ApiError(422, "invalid_domain", str(exc)) from None
        except InvalidInput as exc:
            raise ApiError(422, "invalid_reference", str(exc)) from None
        label = name or (Path(file.filename or "").stem[:200] or "reference")
        ref = crud.create_reference(session, club_id=club.id, name=label)
        final_dir = storage.reference_dir(ref.id)
        ref.bvh_path = str(storage.move(bvh, final_dir / "reference.bvh"))
        if domain_config is not None:
            # Beside the BVH under the name the engine looks for (engine.reference.domain).
            domain_file = final_dir / "reference.domain.json"
            domain_file.write_text(json.dumps(validation.engine_domain(domain_config)))
            ref.domain_path = str(domain_file)
        ref.domain_config = domain_config
        ref.derived = derived
        session.commit()
        return ref
    except BaseException:
        session.rollback()
        Storage.remove(final_dir)
        raise
    finally:
        Storage.remove(tmp)


@router.get("", response_model=list[ReferencePublic], summary="The club's references")
def list_references(club: CurrentClub, session: SessionDep, page: PageDep):
    return crud.list_references(session, club_id=club.id, limit=page.limit, offset=page.offset)


@router.get(
    "/{reference_id}", response_model=ReferencePublic, summary="One reference",
    responses=errors(404),
)  # fmt: skip
def read_reference(reference_id: int, club: CurrentClub, session: SessionDep):
    ref = crud.get_reference(session, club_id=club.id, reference_id=reference_id)
    if ref is None:
        raise not_found("reference", reference_id)
    return ref


@router.delete(
    "/{reference_id}", status_code=204, summary="Delete a reference no analysis uses",
    responses=errors(404, 409),
)  # fmt: skip
def delete_reference(
    reference_id: int, club: CurrentClub, session: SessionDep, storage: StorageDep
) -> Response:
    ref = crud.get_reference(session, club_id=club.id, reference_id=reference_id)
    if ref is None:
        raise not_found("reference", reference_id)
    if crud.reference_in_use(session, ref):
        raise ApiError(
            409, "conflict", f"reference {reference_id} is used by analyses; delete them first"
        )
    session.delete(ref)
    session.commit()
    Storage.remove(storage.reference_dir(reference_id))
    return Response(status_code=204)
