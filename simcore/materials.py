"""Surface reflectance: the four-parameter monostatic BRDF (Eq. 6) and the material library.

The library is the paper's Table 1 ("Windsurfing" there is a mistranslation of solar panel)
plus a true Lambertian. Which target part gets which material is data: a material map TOML
next to each target.

The model: docs/physics.md#target-model (Eq. 6: docs/physics.md#eq-6; Table 1:
docs/physics.md#table-1).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .tomlfile import read_toml_file


@dataclass(frozen=True)
class Material:
    """Eq. 6 parameters: rho(theta) = A / cos^6 exp(-tan^2 / s^2) + B cos^m   [1/sr]."""

    name: str
    A: float  # specular amplitude [1/sr]
    B: float  # diffuse amplitude [1/sr]
    m: float  # diffuse exponent [1]
    s: float  # surface slope (roughness) [1]
    label: str = ""

    def __post_init__(self):
        if self.A < 0 or self.B < 0:
            raise ValueError(f"material {self.name!r}: A and B must be >= 0")
        if self.A > 0 and not self.s > 0:
            raise ValueError(f"material {self.name!r}: s must be > 0 when A > 0")


# Table 1 of the paper (A, B in 1/sr), plus a true Lambertian white plate (albedo 1:
# B = 1/pi, m = 0; Eq. 30 carries the cos(theta) of the projected area).
LIBRARY: dict[str, Material] = {
    m.name: m
    for m in (
        Material("ideal_diffuse", 0.0, 1.0, 1.0, 1.0, "ideal diffuse (Table 1)"),
        Material("ideal_specular", 1.0, 0.0, 0.0, 0.25, "ideal specular (Table 1)"),
        Material("solar_panel", 0.5, 0.03, 4.0, 0.05, "solar panel (Table 1)"),
        Material("coating_1", 0.55, 0.05, 2.0, 0.25, "coating 1 (Table 1)"),
        Material("coating_2", 0.65, 0.04, 3.0, 0.15, "coating 2 (Table 1)"),
        Material("lambertian", 0.0, 1.0 / np.pi, 0.0, 1.0, "Lambertian, albedo 1"),
    )
}
MATERIAL_NAMES = tuple(LIBRARY)


def brdf(cos_theta, A, B, m, s):
    """Monostatic BRDF of Eq. 6, stable at and past grazing incidence.

    Parameters
    ----------
    cos_theta : (...) float
        Cosine of the incidence angle, measured towards the lidar.
    A, B, m, s : (...) float, broadcastable
        Material parameters (A, B in 1/sr).

    Returns
    -------
    rho : (...) float64 [1/sr]
        Finite and >= 0 everywhere; 0 where cos_theta <= 0 (a back face). The specular term is
        evaluated in log space, exp(log A - tan^2/s^2 - 6 log cos), and skipped where A == 0.
    """
    c = np.asarray(cos_theta, dtype=np.float64)
    A, B, m, s = (np.asarray(x, dtype=np.float64) for x in (A, B, m, s))
    front = c > 0
    cc = np.where(front, np.minimum(c, 1.0), 1.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        tan2 = (1.0 - cc * cc) / (cc * cc)  # inf for a denormal cos: the specular term is then 0
        log_spec = np.log(np.where(A > 0, A, 1.0)) - tan2 / np.where(s > 0, s, 1.0) ** 2
        log_spec = log_spec - 6.0 * np.log(cc)
    spec = np.where(A > 0, np.exp(np.minimum(log_spec, 700.0)), 0.0)
    diffuse = B * cc**m
    return np.where(front, spec + diffuse, 0.0)


def brdf_bistatic(cos_i, cos_r, cos_h, A, B, m, s):
    """Bistatic extension of Eq. 6: light arriving at incidence angle theta_i, leaving towards
    the observer at theta_r, theta_h the angle between the normal and the half vector of the two
    directions   [1/sr]:

        f = A exp(-tan^2 theta_h / s^2) / (cos^4 theta_h cos theta_i cos theta_r)
            + B (cos theta_i cos theta_r)^(m / 2)

    The specular term is the Torrance-Sparrow / Cook-Torrance microfacet form with the Beckmann
    facet distribution D(theta_h) ~ exp(-tan^2 theta_h / s^2) / cos^4 theta_h over
    cos theta_i cos theta_r (Cook & Torrance 1982, ACM Trans. Graph. 1(1) 7-24; Beckmann &
    Spizzichino 1963), its Fresnel, shadowing and normalisation constants in A, as Eq. 6 has
    them; the diffuse term is Minnaert's reciprocal form (Minnaert 1941, ApJ 93, 403). Both
    obey reciprocity (i <-> r) and with the source behind the observer (theta_i = theta_r =
    theta_h = theta) give Eq. 6: A exp(-tan^2 / s^2) / cos^6 + B cos^m. Evaluated in log space
    like :func:`brdf`; 0 where either cosine is <= 0 (lit from behind or seen from behind).

    cos_i, cos_r, cos_h : (...) float -- cosines of theta_i, theta_r, theta_h
    A, B, m, s : (...) float, broadcastable -- the material's Eq. 6 parameters
    """
    ci = np.asarray(cos_i, dtype=np.float64)
    cr = np.asarray(cos_r, dtype=np.float64)
    ch = np.asarray(cos_h, dtype=np.float64)
    A, B, m, s = (np.asarray(x, dtype=np.float64) for x in (A, B, m, s))
    front = (ci > 0) & (cr > 0) & (ch > 0)
    ci = np.where(front, np.minimum(ci, 1.0), 1.0)
    cr = np.where(front, np.minimum(cr, 1.0), 1.0)
    ch = np.where(front, np.minimum(ch, 1.0), 1.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        tan2 = (1.0 - ch * ch) / (ch * ch)
        log_spec = np.log(np.where(A > 0, A, 1.0)) - tan2 / np.where(s > 0, s, 1.0) ** 2
        log_spec = log_spec - 4.0 * np.log(ch) - np.log(ci) - np.log(cr)
    spec = np.where(A > 0, np.exp(np.minimum(log_spec, 700.0)), 0.0)
    diffuse = B * (ci * cr) ** (0.5 * m)
    return np.where(front, spec + diffuse, 0.0)


def material_brdf(cos_theta, material: Material):
    """Eq. 6 for one library material."""
    return brdf(cos_theta, material.A, material.B, material.m, material.s)


def parameter_table(names) -> np.ndarray:
    """(n_materials, 4) float64 array of A, B, m, s for the given material names, in order."""
    unknown = [n for n in names if n not in LIBRARY]
    if unknown:
        raise KeyError(
            f"unknown material {unknown[0]!r}; the library has {', '.join(MATERIAL_NAMES)}"
        )
    return np.array([[LIBRARY[n].A, LIBRARY[n].B, LIBRARY[n].m, LIBRARY[n].s] for n in names])


def read_material_map(path: str | Path) -> dict[str, str]:
    """Read a material map TOML: a [materials] table of part name -> library material name."""
    data = read_toml_file(path, "material map", ValueError)
    table = data.get("materials", {})
    default = data.get("default", "coating_2")
    mapping = {str(k): str(v) for k, v in table.items()}
    for part, name in [*mapping.items(), ("default", default)]:
        if name not in LIBRARY:
            raise ValueError(
                f"{path}: part {part!r} uses unknown material {name!r}; "
                f"the library has {', '.join(MATERIAL_NAMES)}"
            )
    mapping.setdefault("*", default)
    return mapping
