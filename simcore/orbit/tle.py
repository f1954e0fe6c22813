"""Two-line element sets: the two lines checked (line numbers, length, checksum), and the set
parsed by SGP4 with its satellite still in orbit at a given time (SGP4 loads only when a TLE is
given; no numpy: the scene's validation reads this module)."""

from __future__ import annotations

import datetime
import math

from ..errors import SceneError

DIGITS = "0123456789"
# What SGP4's error codes mean (python-sgp4, ``sgp4.api``: SGP4_ERRORS)
SGP4_ERRORS = {
    1: "its mean eccentricity is outside [0, 1) or its semi-major axis below 0.95 Earth radii",
    2: "its mean motion is negative",
    3: "its perturbed eccentricity is outside [0, 1]",
    4: "its semi-latus rectum is negative",
    5: "its orbit is sub-orbital",
    6: "its orbit lies inside the Earth (the satellite has decayed)",
}


def tle_lines(key: str, text: str) -> tuple[str, str]:
    """The two lines of a two-line element set (a title line before them is dropped), each
    checked for its line number, length and checksum (modulo 10); SceneError naming ``key``."""
    lines = [line.rstrip() for line in text.strip().splitlines() if line.strip()]
    if len(lines) == 3:
        lines = lines[1:]
    if len(lines) != 2:
        raise SceneError(f"{key}: a TLE is two lines (1 ... and 2 ...), got {len(lines)}")
    for number, line in zip("12", lines, strict=True):
        if not line.isascii():
            raise SceneError(f"{key}: line {number} has a character that is not ASCII")
        if len(line) != 69 or line[0] != number or line[1] != " ":
            raise SceneError(
                f"{key}: line {number} must be 69 characters starting with '{number} ', got "
                f"{line[:20]!r}... ({len(line)} characters)"
            )
        digits = sum(int(c) for c in line[:68] if c in DIGITS) + line[:68].count("-")
        if line[68] not in DIGITS or digits % 10 != int(line[68]):
            raise SceneError(f"{key}: line {number} fails its checksum (column 69)")
    return lines[0], lines[1]


def check_tle(key: str, text: str, when: datetime.datetime) -> None:
    """The TLE parses (SGP4) and its satellite is still in orbit at ``when`` (UTC)."""
    line1, line2 = tle_lines(key, text)
    from sgp4.api import Satrec, jday  # noqa: PLC0415  (only when a TLE is given)

    sat = Satrec.twoline2rv(line1, line2)
    if sat.error:
        why = SGP4_ERRORS.get(sat.error, "SGP4 cannot propagate it")
        raise SceneError(
            f"{key}: SGP4 cannot use this TLE: {why} (mean motion "
            f"{sat.no_kozai * 1440 / (2 * math.pi):.4g} rev/day; SGP4 error {sat.error})"
        )
    jd, fr = jday(when.year, when.month, when.day, when.hour, when.minute, when.second)
    error, r_km, _ = sat.sgp4(jd, fr + when.microsecond / 86400e6)
    if error:
        what = "has decayed" if error == 6 else f"fails to propagate (SGP4 error {error})"
        raise SceneError(
            f"{key}: the satellite {what} at {when:%Y-%m-%dT%H:%M:%SZ} (orbit.epoch_utc + "
            "orbit.time_s)"
        )
