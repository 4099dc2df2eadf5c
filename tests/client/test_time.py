from datetime import UTC, datetime

import pytest

from client import parse_frame_time


@pytest.mark.parametrize(("value", "expected"), [
    (None, None),
    (0, datetime(1970, 1, 1, tzinfo=UTC)),
    (1_780_000_000.5, datetime.fromtimestamp(1_780_000_000.5, UTC)),
    ("2026-03-01T12:00:00.25Z", datetime(2026, 3, 1, 12, 0, 0, 250_000, tzinfo=UTC)),
    ("2026-03-01T14:00:00+02:00", datetime(2026, 3, 1, 12, 0, 0, tzinfo=UTC)),
    ("2026-03-01T12:00:00", datetime(2026, 3, 1, 12, 0, 0, tzinfo=UTC)),
    ("2026-060T12:00:00.5", datetime(2026, 3, 1, 12, 0, 0, 500_000, tzinfo=UTC)),
])
def test_times(value: object, expected: datetime | None) -> None:
    assert parse_frame_time(value) == expected  # type: ignore[arg-type]


@pytest.mark.parametrize("value", ["yesterday", float("nan"), True])
def test_bad_times(value: object) -> None:
    with pytest.raises(ValueError):
        parse_frame_time(value)  # type: ignore[arg-type]
