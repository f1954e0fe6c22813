"""The lit side in the 3D scene view: with a Sun the state holds, for every facet of the target,
whether it faces the Sun and whether it faces the Earth (n . s > 0, by the facet's outward
normal), the legend's counts and the colours the page draws; by night nothing."""

from __future__ import annotations

import numpy as np
import pytest
from support.app_helpers import change, small_app

from app.payloads import encode, scene3d
from simcore.sun import direction_from_angles


@pytest.fixture(scope="module")
def app():
    with small_app(pixels=32) as lmapd:
        yield lmapd


def facet_normals(model) -> tuple[np.ndarray, np.ndarray]:
    """Each facet's unit normal from its corners' cross product (the mesh frame), and its area
    [m^2]: computed here, not by the mesh library."""
    v = model.mesh.vertices
    f = model.mesh.faces
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    twice_area = np.linalg.norm(n, axis=1)
    return n / np.maximum(twice_area, 1e-300)[:, None], twice_area / 2.0


def bits(lit: dict, name: str, n: int) -> np.ndarray:
    """The unpacked flags (n,) bool of ``lit_side[name]``."""
    return np.unpackbits(encode.decoded(lit[name]), count=n).astype(bool)


def clear_facets(cos: np.ndarray, area: np.ndarray, k: int = 40) -> np.ndarray:
    """``k`` facets spread over the mesh whose normal is clearly on one side of the direction
    (|cos| > 0.05, not degenerate), half facing it and half not."""
    chosen = []
    for side in (cos > 0.05, cos < -0.05):
        candidates = np.flatnonzero(side & (area > 0))
        chosen.append(candidates[np.linspace(0, len(candidates) - 1, k // 2).astype(int)])
    return np.concatenate(chosen)


def test_by_night_there_is_no_lit_side(app):
    change(app, sun_mode="none")
    assert app.state.lit_side is None


@pytest.mark.parametrize(("azimuth", "elevation"), [(20.0, 10.0), (-120.0, 55.0)])
def test_the_lit_flags_are_the_facets_that_face_the_sun_and_the_earth(app, azimuth, elevation):
    change(app, sun_mode="manual", sun_azimuth_deg=azimuth, sun_elevation_deg=elevation)
    model = app.engine.model
    lit = app.state.lit_side
    n = len(model.mesh.faces)
    assert lit["n_facets"] == n
    normals, area = facet_normals(model)
    to_mesh = model.body_from_mesh.T  # body -> mesh frame
    for name, body in (
        ("sun", direction_from_angles(azimuth, elevation)),
        ("earth", np.array([0.0, 0.0, 1.0])),  # the Earth below the target: its nadir, +z
    ):
        cos = normals @ (to_mesh @ body)
        facets = clear_facets(cos, area)
        assert np.array_equal(bits(lit, name, n)[facets], cos[facets] > 0), name
    # the legend counts every facet once; the page's colours follow the bits through the palette
    sun, earth = bits(lit, "sun", n), bits(lit, "earth", n)
    assert sum(r["facets"] for r in lit["rows"]) == n
    assert lit["rows"][0]["facets"] == np.count_nonzero(sun & ~earth)
    assert lit["palette"][1] == list(encode.rgb_of(scene3d.SUN_COLOR))
    assert lit["palette"][2] == list(encode.rgb_of(scene3d.EARTH_COLOR))


def test_in_the_earths_shadow_no_facet_is_sunlit_and_without_the_earth_none_faces_it(app):
    model = app.engine.model
    n = len(model.mesh.faces)
    lit = scene3d.lit_side(model, None, np.array([1.0, 0.0, 0.0]))
    assert not bits(lit, "sun", n).any() and bits(lit, "earth", n).any()
    assert lit["rows"][0] == {
        "label": "sunlit: none (Earth's shadow)",
        "color": scene3d.SUN_COLOR,
        "facets": 0,
    }
    lit = scene3d.lit_side(model, np.array([1.0, 0.0, 0.0]), None)
    assert not bits(lit, "earth", n).any()
    assert [r["label"] for r in lit["rows"]] == ["faces the Sun", "faces neither"]
