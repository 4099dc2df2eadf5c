"""Frame times: a recording's ``time`` is an ISO 8601 string or POSIX seconds, always UTC."""

from __future__ import annotations

import math
import re
from datetime import UTC, datetime

__all__ = ["parse_frame_time"]

_DOY = re.compile(r"^(\d{4})-(\d{3})T(\d{2}):(\d{2}):(\d{2}(?:\.\d+)?)Z?$")


def parse_frame_time(value: float | int | str | None) -> datetime | None:
    """The UTC instant of a frame's ``time``, or None when the frame has none.

    * a number: seconds since 1970-01-01T00:00:00 UTC (POSIX time, no leap seconds);
    * a string: ISO 8601 (``2026-03-01T12:00:00.25Z``, ``...+02:00``; no offset = UTC),
      or CCSDS day-of-year ``2026-060T12:00:00.25``.

    Raises ``ValueError`` for anything else.
    """
    if value is None:
        return None
    if isinstance(value, bool):
        raise ValueError("time must be a number or a string")
    if isinstance(value, int | float):
        if not math.isfinite(value):
            raise ValueError("time must be finite")
        return datetime.fromtimestamp(float(value), UTC)
    text = value.strip()
    m = _DOY.match(text)
    if m:
        year, doy, hh, mm, ss = m.groups()
        base = datetime.strptime(f"{year}-{doy}", "%Y-%j").replace(tzinfo=UTC)
        sec = float(ss)
        return base.replace(hour=int(hh), minute=int(mm), second=int(sec),
                            microsecond=round((sec - int(sec)) * 1e6) % 1_000_000)
    try:
        t = datetime.fromisoformat(text)
    except ValueError:
        raise ValueError(f"not an ISO 8601 time: {value!r}") from None
    return t.replace(tzinfo=UTC) if t.tzinfo is None else t.astimezone(UTC)
