"""The filming check of the upload page (issue 21 item 6): one frame in, what to change out.

The page sends the first frame of the chosen video as a picture before anything is uploaded,
so a performer whose feet are cut off hears it in a second, not after the analysis. The model
runs in this process (0.1-0.2 s a frame on one core), one frame at a time: a semaphore keeps
a burst of checks from taking every core from the API.
"""

from __future__ import annotations

import threading
from typing import Annotated

import cv2
import numpy as np
from fastapi import APIRouter, File, UploadFile
from fastapi.concurrency import run_in_threadpool
from pydantic import BaseModel

from app.api.deps import CurrentPrincipal
from app.api.errors import ApiError, errors
from worker.engine_surface import InvalidInput, check_framing

router = APIRouter(prefix="/framing", tags=["analyses"], responses=errors(401, 429))

#: A frame larger than this is not one video frame as the page sends it.
MAX_FRAME_BYTES = 4_000_000
MAX_FRAME_SIDE = 4096
_ONE_AT_A_TIME = threading.Semaphore(1)


class FramingPublic(BaseModel):
    person_found: bool
    out_of_view: list[str]
    body_share: float
    people: int
    problems: list[str]


def _check(data: bytes) -> FramingPublic:
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        raise ApiError(422, "invalid_image", "the frame is not a JPEG or PNG picture")
    if max(image.shape[:2]) > MAX_FRAME_SIDE:
        raise ApiError(422, "invalid_image", f"the frame is over {MAX_FRAME_SIDE} pixels wide")
    with _ONE_AT_A_TIME:
        try:
            f = check_framing(cv2.cvtColor(image, cv2.COLOR_BGR2RGB))
        except InvalidInput as exc:
            raise ApiError(422, "invalid_image", str(exc)) from None
    return FramingPublic(person_found=f.person_found, out_of_view=list(f.out_of_view),
                         body_share=round(f.body_share, 3), people=f.people,
                         problems=list(f.problems))  # fmt: skip


@router.post(
    "", response_model=FramingPublic, responses=errors(413, 422),
    summary="Check how a video is filmed, from one frame, before uploading it",
)  # fmt: skip
async def check_frame(
    frame: Annotated[UploadFile, File(description="One video frame, JPEG or PNG.")],
    who: CurrentPrincipal,
) -> FramingPublic:
    """Whether a person is in view, whole, large enough and alone; ``problems`` says what to
    change, one sentence each (empty when the framing looks right)."""
    data = await frame.read(MAX_FRAME_BYTES + 1)
    if len(data) > MAX_FRAME_BYTES:
        raise ApiError(413, "too_large", f"a frame is at most {MAX_FRAME_BYTES // 1_000_000} MB")
    return await run_in_threadpool(_check, data)
