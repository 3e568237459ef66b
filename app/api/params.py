"""Path, query and form parameters typed to what the database holds.

Ids are ``Integer`` columns: 32-bit signed on PostgreSQL and MySQL, so 1 to 2**31 - 1 on
every backend. A larger id would overflow the driver (a 500 before this); bounded here it is a
422 naming the parameter. Times are ISO 8601 date-times only: pydantic would read a number
as unix seconds or milliseconds, guessing by its size, which no client should rely on.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Annotated

from fastapi import Form, Path, Query
from pydantic import BeforeValidator

#: The largest value of an ``Integer`` id column on every backend (32-bit signed).
MAX_ID = 2**31 - 1

#: A row id in the path (``/references/{reference_id}``).
DbId = Annotated[int, Path(ge=1, le=MAX_ID, description="A row id.")]
#: An optional row id in the query (a filter).
DbIdQuery = Annotated[int | None, Query(ge=1, le=MAX_ID)]
#: A row id in a form (multipart uploads).
DbIdForm = Annotated[int, Form(ge=1, le=MAX_ID)]


def _iso_instant(value: object) -> datetime:
    """An ISO 8601 date-time as an aware UTC datetime (no zone: UTC); numbers refused."""
    if isinstance(value, datetime):
        when = value
    elif isinstance(value, str):
        try:
            when = datetime.fromisoformat(value)
        except ValueError:
            raise ValueError(
                "must be an ISO 8601 date-time such as 2024-05-01T12:00:00Z or 2024-05-01"
            ) from None
    else:
        raise ValueError("must be an ISO 8601 date-time string")
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    try:
        return when.astimezone(UTC)
    except OverflowError:
        raise ValueError("must lie within the years 1 to 9999 in UTC") from None


#: An instant in the query: ISO 8601 (``2024-05-01T12:00:00Z``, ``2024-05-01``); without
#: a zone it is UTC.
Instant = Annotated[datetime, BeforeValidator(_iso_instant)]
