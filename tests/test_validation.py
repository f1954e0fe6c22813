"""The check against Mitsuba 3 (``make validate``, validation/): its own arithmetic, the committed
figures' schema, and the page's table made from them. Nothing here needs Mitsuba: its renders
are ``make validate``'s, and this suite never imports it."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from validation import compare
from validation.scenes import (
    DISTANCE_M,
    FOV_RAD,
    PLATE_INCIDENCE_DEG,
    pixel_tangent,
    plate_corners_m,
    scenes,
)

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
FIGURES = DOCS / "data" / "validation.json"


def hooks():
    spec = importlib.util.spec_from_file_location("docs_generated", DOCS / "hooks" / "generated.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_moments_of_a_uniform_histogram_are_its_centre_and_width_over_root_12():
    t = np.linspace(0.0, 1.0, 100_001)
    mean, rms = compare.moments(t, np.ones_like(t))
    assert mean == pytest.approx(0.5, abs=1e-12)
    assert rms == pytest.approx(1.0 / np.sqrt(12.0), rel=1e-4)  # the grid's own 1/N term


def test_moments_refuse_an_echo_with_no_energy():
    with pytest.raises(ValueError, match="no energy"):
        compare.moments([1.0, 2.0], [0.0, 0.0])


def test_interior_pixels_are_those_with_eight_lit_neighbours():
    lit = np.zeros((8, 8), bool)
    lit[1:6, 2:7] = True  # 5 x 5
    inner = compare.interior(lit)
    assert inner.sum() == 9 and inner[2:5, 3:6].all()
    lit[3, 4] = False  # a hole darkens itself and its eight neighbours' interior
    assert compare.interior(lit).sum() == 0


def test_lit_pixels_count_each_side_and_the_energy_of_the_pixels_one_side_alone_has():
    a = np.array([[1.0, 0.0], [2.0, 0.0]])
    b = np.array([[1.0, 0.5], [0.0, 0.0]])
    out = compare.lit_pixels(a, b)
    assert (out["a"], out["b"], out["both"], out["only_a"], out["only_b"]) == (2, 2, 1, 1, 1)
    assert out["only_a_energy_share"] == pytest.approx(2.0 / 3.0)
    assert out["only_b_energy_share"] == pytest.approx(0.5 / 1.5)


def test_relative_differences_leave_out_nothing_of_the_mask():
    a, b = np.array([1.0, 2.2, 3.0]), np.array([1.0, 2.0, 2.0])
    out = compare.relative(a, b, np.array([True, True, False]))
    assert out["n"] == 2 and out["max"] == pytest.approx(0.1) and out["mean"] == pytest.approx(0.05)


def tilted_plate(side_m, incidence_deg, distance_m):
    h, b = side_m / 2.0, np.radians(incidence_deg)
    corners = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])
    rot = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(b), -np.sin(b)], [0.0, np.sin(b), np.cos(b)]])
    return corners @ rot.T + [0.0, 0.0, distance_m]


@pytest.mark.parametrize("incidence_deg", [30.0, 60.0])
def test_the_plate_quadrature_tends_to_the_far_field_closed_form(incidence_deg):
    # far away (1e5 sides) the 1/r^4 and the perspective fade: the rms width is the uniform
    # depth's, 2 s sin(b) / (c sqrt 12), to the plate's relative size
    side = 1.0
    mean, rms = compare.plate_echo(tilted_plate(side, incidence_deg, 1e5))
    assert rms == pytest.approx(compare.far_field_plate_width_s(side, incidence_deg), rel=1e-4)
    assert mean == pytest.approx(2e5 / compare.C, rel=1e-9)
    # near, it differs from it by the weighting across the depth (1.2e-4 at 500 m, 30 deg)
    near = compare.plate_echo(tilted_plate(8.0, incidence_deg, 500.0))[1]
    assert abs(near / compare.far_field_plate_width_s(8.0, incidence_deg) - 1.0) > 2e-5


def test_the_plate_quadrature_converges():
    corners = tilted_plate(7.0, 60.0, 500.0)
    assert compare.plate_echo(corners, 16) == pytest.approx(compare.plate_echo(corners, 64), 1e-9)


@pytest.mark.parametrize("incidence_deg", PLATE_INCIDENCE_DEG)
def test_each_plate_is_tilted_by_its_incidence_with_its_edges_on_half_pixel_lines(incidence_deg):
    corners = plate_corners_m(incidence_deg)
    normal = np.cross(corners[1] - corners[0], corners[3] - corners[0])
    normal /= np.linalg.norm(normal)
    assert np.degrees(np.arccos(abs(normal[2]))) == pytest.approx(incidence_deg, abs=1e-9)
    assert (corners - [0.0, 0.0, DISTANCE_M]) @ normal == pytest.approx(np.zeros(4), abs=1e-9)
    pixels = corners[:, :2] / corners[:, 2:] / pixel_tangent()  # image position from the centre
    assert pixels - np.floor(pixels) == pytest.approx(np.full((4, 2), 0.5), abs=1e-9)
    # inside the lit disc of half-angle fov / 2 (the beam fills the array's inscribed circle)
    assert np.hypot(*pixels.T).max() * pixel_tangent() < np.tan(FOV_RAD / 2.0)


def test_the_committed_figures_cover_every_scene_and_fidelity():
    fig = json.loads(FIGURES.read_text(encoding="utf-8"))
    assert set(fig["scenes"]) == set(scenes())
    for name, scene in fig["scenes"].items():
        assert set(scene["fidelity"]) == {"default", "interactive", "reference"}, name
        for f in scene["fidelity"].values():
            for key in ("lit", "energy_interior", "mean_delay_ps", "t_half_ps", "whole_echo"):
                assert key in f, (name, key)
        # every path in the histograms' windows: their sum is the steady image's to float32's
        # sums of 1,024 samples per pixel (at most 1024 x 6e-8 = 6e-5 apart)
        assert scene["histogram_share"] == pytest.approx(1.0, abs=1e-4), name
    for albedo in ("1", "0.5"):
        two, many = (fig["multi_bounce_mro"][albedo][f"depth_{d}"] for d in (3, 16))
        assert 1.0 <= two["energy_ratio"] <= many["energy_ratio"]  # more bounces, more light


def test_the_validation_page_shows_the_table_generated_from_the_committed_figures():
    page = (DOCS / "validation.md").read_text(encoding="utf-8")
    assert "<!-- generated: validation -->" in page
    table = hooks().validation_markdown()
    fig = json.loads(FIGURES.read_text(encoding="utf-8"))
    rows = [line for line in table.splitlines() if line.startswith("| ") and "sub-ray" in line]
    assert len(rows) == sum(len(s["fidelity"]) for s in fig["scenes"].values())
    lit = fig["scenes"]["mro"]["fidelity"]["default"]["lit"]
    assert f"{lit['a']} / {lit['b']}" in table
    assert fig["mitsuba"] in table and fig["mitransient"] in table


def test_importing_the_validation_loads_no_renderer():
    # Mitsuba is loaded by validation.render.load_mitsuba alone, when a render is asked for
    probe = (
        "import sys, validation.render, validation.compare, validation.scenes, "
        "validation.__main__; print(sorted(m for m in sys.modules "
        "if m.split('.')[0] in ('mitsuba', 'mitransient', 'drjit')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"
