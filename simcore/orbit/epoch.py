"""UTC epochs: an ISO 8601 date and time read as UTC, and the span of the ephemeris the Sun is
taken from (no numpy: the scene's validation reads this module)."""

from __future__ import annotations

import datetime

from ..errors import SceneError

# The span of the JPL DE421 ephemeris this simulator uses for the Sun (the `de421` package; its
# documented span, "1900 through 2050"): the UTC dates orbit.epoch_utc (and epoch + time) may take.
EPHEMERIS_FIRST_UTC = "1900-01-01T00:00:00+00:00"
EPHEMERIS_LAST_UTC = "2050-12-31T00:00:00+00:00"


def parse_utc(key: str, text: str) -> datetime.datetime:
    """An ISO 8601 date and time as an aware UTC datetime (no zone given: UTC); SceneError
    naming ``key`` if it does not parse."""
    try:
        when = datetime.datetime.fromisoformat(text.strip())
    except (ValueError, AttributeError):
        raise SceneError(
            f"{key} = {text!r} is not an ISO 8601 date and time (e.g. 2024-03-20T12:00:00Z)"
        ) from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=datetime.UTC)
    try:
        return when.astimezone(datetime.UTC)
    except OverflowError:  # e.g. 0001-01-01T00:00+01:00 is before year 1 in UTC
        raise SceneError(
            f"{key} = {text!r} is outside the dates this simulator reads (years 1 to 9999 UTC)"
        ) from None
