"""The Sun: its spectrum at the laser line, its direction from an ephemeris, the Earth's shadow.

- Solar spectral irradiance at 1 AU outside the atmosphere: the ASTM E-490 AM0 table (a slice,
  ``data/astm_e490_am0_900_1700nm.csv``), integrated over the receiver's band-pass filter.
- The Sun's geocentric position: the JPL DE421 planetary ephemeris (Folkner, Williams & Boggs
  2009, JPL IPN Progress Report 42-178), shipped as the ``de421`` package and read with
  ``jplephem``; UTC to TDB through skyfield's built-in leap-second table. Nothing downloads.
- Orbits: the Table 3 elements (``simcore.orbit``, ECI read as the GCRS of the epoch) or two-line
  element sets through SGP4 (skyfield's ``EarthSatellite``, positions in the GCRS).
- The Earth's shadow: a cylinder of one Earth radius behind the Earth (no penumbra: at 695 km
  the penumbra is about 28 km wide and the target crosses it in about 9 s).

The model: docs/physics.md#background.
"""

from __future__ import annotations

import datetime
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from .errors import SceneError
from .orbit.attitude import lvlh_attitude
from .orbit.elements import PAPER_IMAGING, PAPER_TARGET, R_EARTH_M
from .orbit.epoch import parse_utc
from .orbit.propagation import propagate
from .orbit.tle import tle_lines
from .scene.model import Scene

AU_M = 149_597_870_700.0  # [m] the astronomical unit (IAU 2012 Resolution B2, exact)
SOLAR_TABLE = Path(__file__).resolve().parent / "data" / "astm_e490_am0_900_1700nm.csv"
_SECONDS_PER_DAY = 86400.0


# ----------------------------------------------------------------------------------------------
# the solar spectrum
# ----------------------------------------------------------------------------------------------
@lru_cache(maxsize=1)
def solar_table() -> tuple[np.ndarray, np.ndarray]:
    """The ASTM E-490 AM0 slice: wavelength (n,) [m] and spectral irradiance at 1 AU (n,)
    [W m^-2 m^-1] (the table's W m^-2 um^-1 times 1e6)."""
    data = np.loadtxt(SOLAR_TABLE, delimiter=",", comments="#", skiprows=8)
    wavelength_m, irradiance = data[:, 0] * 1e-6, data[:, 1] * 1e6
    for a in (wavelength_m, irradiance):
        a.setflags(write=False)
    return wavelength_m, irradiance


def spectral_irradiance_w_m3(wavelength_m) -> np.ndarray:
    """E_lambda at 1 AU [W m^-2 m^-1], linear between the table's 2 nm nodes."""
    lam, e = solar_table()
    return np.interp(wavelength_m, lam, e, left=np.nan, right=np.nan)


def in_band_irradiance_w_m2(wavelength_m: float, filter_width_m: float) -> float:
    """Solar irradiance at 1 AU inside a flat-top filter of full width ``filter_width_m``
    centred on ``wavelength_m`` [W m^-2]: the exact integral of the table's piecewise-linear
    E_lambda over the band (E_lambda(lambda) x width for a band narrower than the 2 nm nodes
    around a line between them). Before the filter's transmittance."""
    lam, e = solar_table()
    lo, hi = wavelength_m - filter_width_m / 2.0, wavelength_m + filter_width_m / 2.0
    if not (lam[0] <= lo and hi <= lam[-1]):
        raise SceneError(
            f"the filter band {lo:g}-{hi:g} m lies outside the solar table "
            f"({lam[0]:g}-{lam[-1]:g} m): check laser.wavelength_m and receive.filter_width_m"
        )
    inner = (lam > lo) & (lam < hi)
    x = np.concatenate([[lo], lam[inner], [hi]])
    y = np.interp(x, lam, e)
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(x)))


# ----------------------------------------------------------------------------------------------
# time and the ephemeris
# ----------------------------------------------------------------------------------------------
@lru_cache(maxsize=1)
def _timescale():
    from skyfield.api import load  # noqa: PLC0415  (only with a Sun from the orbit)

    return load.timescale(builtin=True)


@lru_cache(maxsize=1)
def _ephemeris():
    import de421  # noqa: PLC0415
    from jplephem.ephem import Ephemeris  # noqa: PLC0415

    return Ephemeris(de421)


def tdb_julian_date(epoch: datetime.datetime, t_s) -> np.ndarray:
    """(n,) TDB Julian dates of ``epoch`` (aware UTC) plus ``t_s`` [s] (leap seconds from
    skyfield's built-in table; a leap second inside the interval shifts the Sun by 0.04 arcsec)."""
    t0 = _timescale().from_datetime(epoch)
    return t0.tdb + np.atleast_1d(np.asarray(t_s, dtype=np.float64)) / _SECONDS_PER_DAY


def sun_position_gcrs_m(jd_tdb) -> np.ndarray:
    """(n, 3) the Sun's geometric position from the Earth's centre, ICRF axes [m], from DE421:
    Sun minus (Earth-Moon barycentre minus Moon / (1 + EMRAT)). Light time and aberration are
    left out (the direction moves by about 20 arcsec)."""
    eph = _ephemeris()
    jd = np.atleast_1d(np.asarray(jd_tdb, dtype=np.float64))
    sun = eph.position("sun", jd)
    earth = eph.position("earthmoon", jd) - eph.position("moon", jd) / (1.0 + eph.EMRAT)
    return ((sun - earth) * 1e3).T.reshape(len(jd), 3)


# ----------------------------------------------------------------------------------------------
# orbits: the Table 3 elements or TLEs
# ----------------------------------------------------------------------------------------------
def satellite_states(
    scene: Scene, which: str, t_s, j2: bool | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """GCRS position (n, 3) [m] and velocity (n, 3) [m/s] of the ``which`` satellite
    ("target" or "imaging") at ``t_s`` [s] after ``orbit.epoch_utc``: from its TLE through SGP4
    if the scene gives TLEs, else the Table 3 elements (two-body, or secular J2 when
    ``orbit.j2`` or ``j2``), whose ECI frame is read as the GCRS of the epoch."""
    o = scene.orbit
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    if o.target_tle:
        text = o.target_tle if which == "target" else o.imaging_tle
        key = f"orbit.{which}_tle"
        if not text:
            raise SceneError(f"{key}: the fly-around needs both TLEs (target and imaging)")
        from skyfield.api import EarthSatellite  # noqa: PLC0415

        ts = _timescale()
        sat = EarthSatellite(*tle_lines(key, text), ts=ts)
        jd = tdb_julian_date(parse_utc("orbit.epoch_utc", o.epoch_utc), t)
        at = sat.at(ts.tdb_jd(jd))
        if np.any(np.asarray(at.message) != None):  # noqa: E711  (skyfield's per-time errors)
            raise SceneError(f"{key}: SGP4 fails over these times ({at.message})")
        return at.position.m.T.copy(), at.velocity.m_per_s.T.copy()
    elements = PAPER_TARGET if which == "target" else PAPER_IMAGING
    return propagate(elements, t, j2=o.j2 if j2 is None else j2)


# ----------------------------------------------------------------------------------------------
# the geometry of one frame
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class SunGeometry:
    """The Sun and the Earth seen from the target, in the target body frame.

    direction_body : (3,) unit vector towards the Sun
    distance_m : the Sun's distance [m] (irradiance scales as (1 AU / distance)^2)
    earth_center_body_m : (3,) the Earth's centre [m] (along +z of a nadir-pointing body)
    eclipsed : the target is in the Earth's shadow (cylinder model)
    """

    direction_body: np.ndarray
    distance_m: float
    earth_center_body_m: np.ndarray
    eclipsed: bool


def direction_from_angles(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """(3,) unit vector at ``azimuth_deg`` from +x towards +y and ``elevation_deg`` above the
    x-y plane towards -z (the target body frame's zenith, its z axis pointing at the Earth)."""
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), -math.sin(el)])


def in_shadow(position_m, sun_direction) -> np.ndarray:
    """(n,) bool: the points ``position_m`` (n, 3) [m, from the Earth's centre] lie in the
    Earth's cylindrical shadow: behind the Earth (r . s < 0) and within one Earth radius of the
    Earth-Sun axis."""
    r = np.atleast_2d(np.asarray(position_m, dtype=np.float64))
    s = np.atleast_2d(np.asarray(sun_direction, dtype=np.float64))
    along = np.sum(r * s, axis=1)
    across = np.linalg.norm(r - along[:, None] * s, axis=1)
    return (along < 0.0) & (across < R_EARTH_M)


def sun_geometry(scene: Scene) -> SunGeometry | None:
    """The Sun and the Earth in the target body frame for this frame; None for ``sun.mode =
    none``. Manual: the Sun at ``sun.azimuth_deg``, ``sun.elevation_deg``, 1 AU away, the Earth
    ``background.target_altitude_m`` below the target. Orbit: the target's orbit at
    ``orbit.time_s`` after ``orbit.epoch_utc``, its body frame its LVLH frame."""
    mode = scene.sun.mode
    if mode == "none":
        return None
    if mode == "manual":
        s_body = direction_from_angles(scene.sun.azimuth_deg, scene.sun.elevation_deg)
        earth = np.array([0.0, 0.0, R_EARTH_M + scene.background.target_altitude_m])
        eclipsed = bool(in_shadow(-earth, s_body)[0])
        return SunGeometry(
            direction_body=s_body, distance_m=AU_M, earth_center_body_m=earth, eclipsed=eclipsed
        )
    return orbit_sun_geometry(scene, np.array([scene.orbit.time_s]))[0]


def orbit_sun_geometry(scene: Scene, t_s, j2: bool | None = None) -> list[SunGeometry]:
    """The Sun and the Earth in the body (LVLH) frame of the scene's target at each ``t_s``
    [s] after ``orbit.epoch_utc``."""
    epoch = parse_utc("orbit.epoch_utc", scene.orbit.epoch_utc)
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    sun_m = sun_position_gcrs_m(tdb_julian_date(epoch, t))
    r, v = satellite_states(scene, "target", t, j2)
    body = lvlh_attitude(r, v)  # columns: body axes in the GCRS
    to_sun = sun_m - r
    distance = np.linalg.norm(to_sun, axis=1)
    s_body = np.einsum("nji,nj->ni", body, to_sun / distance[:, None])
    earth_body = np.einsum("nji,nj->ni", body, -r)
    shadow = in_shadow(r, sun_m / np.linalg.norm(sun_m, axis=1)[:, None])
    return [
        SunGeometry(
            direction_body=s_body[i],
            distance_m=float(distance[i]),
            earth_center_body_m=earth_body[i],
            eclipsed=bool(shadow[i]),
        )
        for i in range(len(t))
    ]
