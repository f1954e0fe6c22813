"""Adaptive refinement: mixed pixels (silhouettes, steps) are re-cast densely, planes are not."""

import numpy as np
import trimesh

import simcore


def step_scene(tmp_path, pixels, step_m=1.5, **overrides):
    """Two plates side by side, one ``step_m`` behind the other (the step along image rows)."""
    a = trimesh.creation.box(extents=(2.0, 4.0, 1e-3))
    a.apply_translation((-1.0, 0.0, 0.0))
    b = trimesh.creation.box(extents=(2.0, 4.0, 1e-3))
    b.apply_translation((1.0, 0.0, step_m))
    path = tmp_path / "step.obj"
    trimesh.util.concatenate([a, b]).export(path)
    base = {
        "target.mesh": str(path),
        "target.scale_m_per_unit": 1.0,
        "pixels": pixels,
        "distance_m": 200.0,
        "target.materials": {"*": "lambertian"},
    }
    return simcore.with_overrides(simcore.Scene(), {**base, **overrides})


def _interior(res, pixels):
    """(pixels, pixels) bool: fully covered pixels two rings in from any partly covered one
    (next to a partly covered pixel the mean range is biased)."""
    interior = res.hits.base.face.reshape(pixels, pixels, -1).min(axis=2) >= 0
    for _ in range(2):
        inner = np.zeros_like(interior)
        inner[1:-1, 1:-1] = (
            interior[1:-1, 1:-1]
            & interior[:-2, 1:-1]
            & interior[2:, 1:-1]
            & interior[1:-1, :-2]
            & interior[1:-1, 2:]
        )
        interior = inner
    return interior


def test_a_tilted_plane_needs_no_refinement_inside_its_silhouette_unless_steep(plate_scene):
    """At 300 m a pixel spans 14 cm: a plane at 45 deg changes range by 14 cm across each pixel,
    one at 70 deg by 39 cm, more than half the pulse's rise time (21 cm): its echo is a plateau
    and its pixels are refined."""
    pipe = simcore.Pipeline()
    knobs = {"fidelity.subrays": 4, "fidelity.refine_subrays": 64}
    for azimuth, steep in ((45.0, False), (70.0, True)):
        scene = plate_scene(size_m=4.0, distance_m=300.0, azimuth_deg=azimuth, pixels=64, **knobs)
        res = pipe.run(scene)
        refined = np.zeros(64 * 64, bool)
        refined[res.hits.refined_pixels] = True
        interior = _interior(res, 64)
        assert interior.sum() > 100
        assert (
            refined.reshape(64, 64)[interior].all()
            if steep
            else not refined[interior.ravel()].any()
        )
        assert refined.sum() > 0  # its silhouette is refined either way


def test_a_depth_step_inside_a_pixel_is_refined_even_when_aligned_with_the_sub_grid(tmp_path):
    # odd pixel count: the middle row straddles the step, its 2 x 2 sub-rays split 2 / 2, which a
    # plane fits exactly; the step shows against the neighbours' gradient
    res = simcore.Pipeline().run(
        step_scene(tmp_path, 65, **{"fidelity.subrays": 4, "fidelity.refine_subrays": 64})
    )
    rows = set((res.hits.refined_pixels // 65).tolist())
    assert 32 in rows


def test_refined_pixels_reproduce_the_reference_exactly(tmp_path):
    pipe = simcore.Pipeline()
    # (with the interactive preset's corner probes, without its merging of sub-ray echoes)
    fast = pipe.run(
        step_scene(tmp_path, 65, preset="interactive", **{"fidelity.merge_window": 0.0})
    )
    ref = pipe.run(step_scene(tmp_path, 65, preset="reference", **{"fidelity.time_step_s": 0.0}))
    refined = fast.hits.refined_pixels
    assert len(refined) > 0
    i_fast = np.searchsorted(fast.echo.pixel, refined)
    i_ref = np.searchsorted(ref.echo.pixel, refined)
    ok = (i_fast < len(fast.echo.pixel)) & (i_ref < len(ref.echo.pixel))
    ok &= fast.echo.pixel[np.minimum(i_fast, len(fast.echo.pixel) - 1)] == refined
    assert ok.sum() > 0
    a = fast.detection.range_true_m[i_fast[ok]]
    b = ref.detection.range_true_m[i_ref[ok]]
    assert np.allclose(a, b, rtol=0, atol=1e-9)


def test_presets_set_their_knobs_and_explicit_keys_win():
    s = simcore.with_overrides(simcore.Scene(), {"preset": "interactive", "fidelity.subrays": 4})
    assert s.preset == "interactive" and s.fidelity.subrays == 4
    assert s.fidelity.refine_subrays == 64
    assert simcore.with_overrides(simcore.Scene(), preset="reference").fidelity.subrays == 64


def bar_scene(tmp_path, **overrides):
    """A 4 m plate at 200 m and, 1 m in front of it, a 4 cm bar along the image's middle: between
    the two middle rows (or columns) of pixel centres of a 64 x 64 array (9.4 cm apart there)."""
    plate = trimesh.creation.box(extents=(4.0, 4.0, 1e-3))
    bar = trimesh.creation.box(extents=(3.0, 0.04, 0.01))
    bar.apply_translation((0.0, 0.0, -1.0))
    path = tmp_path / "bar.obj"
    trimesh.util.concatenate([plate, bar]).export(path)
    base = {
        "target.mesh": str(path),
        "target.scale_m_per_unit": 1.0,
        "pixels": 64,
        "distance_m": 200.0,
        "target.materials": {"*": "lambertian"},
        "preset": "interactive",
    }
    return simcore.with_overrides(simcore.Scene(), {**base, **overrides})


def test_corner_probes_find_a_thin_part_that_every_pixel_centre_misses(tmp_path):
    pipe = simcore.Pipeline()
    centres = pipe.run(bar_scene(tmp_path, **{"fidelity.probe_corners": False}))
    plate_range = np.median(centres.hits.range_m[np.isfinite(centres.hits.range_m)])
    in_front = lambda block: block.range_m < plate_range - 0.5  # noqa: E731
    assert not in_front(centres.hits.base).any()  # no pixel centre sees the bar...
    refined = centres.hits.refined
    assert refined is None or not in_front(refined).any()  # ...so nothing finds it

    probed = pipe.run(bar_scene(tmp_path))
    hits = probed.hits
    rows_or_cols = np.unique(np.divmod(hits.refined_pixels[in_front(hits.refined).any(axis=1)], 64))
    seen = in_front(hits.refined).any(axis=1).sum()
    assert seen >= 2 * 30  # two lines of pixels along the bar (3 m of the 6 m field: 32 a line)
    assert {31, 32} <= set(rows_or_cols.tolist())
    # those pixels are sampled as the reference samples them
    ref = pipe.run(bar_scene(tmp_path, preset="reference"))
    assert abs(probed.detection.p_detect.sum() / ref.detection.p_detect.sum() - 1) < 0.005


def test_corner_probes_refine_one_ring_of_silhouette_pixels_not_two(plate_scene):
    """A straight edge crosses a square pixel if and only if it separates two of its corners:
    with corners, the pixels just outside the silhouette need no refinement."""
    knobs = {"fidelity.subrays": 1, "fidelity.refine_subrays": 64, "fidelity.refine_step_m": 0.05}
    pipe = simcore.Pipeline()
    scene = plate_scene(size_m=4.1, distance_m=300.0, pixels=64, **knobs)
    two = pipe.run(scene).hits.refined_pixels
    one = pipe.run(simcore.with_overrides(scene, {"fidelity.probe_corners": True})).hits
    assert 0 < len(one.refined_pixels) < 0.6 * len(two)
    covered = (one.refined.face >= 0).mean(axis=1)
    assert np.all((covered > 0) & (covered < 1))  # each refined pixel straddles the edge


def _inner_range_rmse(fast, ref):
    """Range RMSE of ``fast`` against ``ref`` over the pixels both light and ``fast`` did not
    refine [m]."""
    common = np.intersect1d(fast.echo.pixel, ref.echo.pixel)
    common = common[~np.isin(common, fast.hits.refined_pixels)]
    i = np.searchsorted(fast.echo.pixel, common)
    j = np.searchsorted(ref.echo.pixel, common)
    err = fast.detection.range_true_m[i] - ref.detection.range_true_m[j]
    return float(np.sqrt(np.mean(err**2))), len(common)


def test_cell_spread_gives_one_ray_the_pulse_broadening_of_a_tilted_pixel(plate_scene):
    """One ray per pixel on a plate tilted 45 deg (9 cm of range across each pixel) puts the
    echo half a millimetre late: the pixel's range spread broadens the pulse and moves its
    half-maximum. With each ray's cell spread (slope from the pixel corners) the single ray
    matches 64 sub-rays to hundredths of a millimetre."""
    pipe = simcore.Pipeline()
    scene = plate_scene(size_m=3.0, tilt_deg=45.0, distance_m=200.0)
    ref = pipe.run(simcore.with_overrides(scene, {"preset": "reference"}))
    spread = pipe.run(simcore.with_overrides(scene, {"preset": "interactive"}))
    points = pipe.run(
        simcore.with_overrides(scene, {"preset": "interactive", "fidelity.cell_spread": False})
    )
    with_spread, n = _inner_range_rmse(spread, ref)
    without, _ = _inner_range_rmse(points, ref)
    assert n > 500
    assert without > 3e-4  # the effect is real: 0.3 mm and more
    assert with_spread < 5e-5 and with_spread < without / 10


def test_pixels_the_edge_of_the_flat_top_beam_crosses_are_refined(plate_scene):
    """A plate wider than the field, lit by the flat-top disc inscribed in the array: the pixels
    the disc's edge crosses are partly lit. Refined, the expected point count is the
    reference's; with their centre ray alone it is percents off (the pulse energy puts the
    partly lit pixels near threshold)."""
    pipe = simcore.Pipeline()
    scene = plate_scene(size_m=10.0, tilt_deg=30.0, distance_m=200.0, pulse_energy_j=3e-5)
    runs = {
        name: pipe.run(simcore.with_overrides(scene, knobs))
        for name, knobs in {
            "reference": {"preset": "reference"},
            "interactive": {"preset": "interactive"},
            "centres": {"preset": "interactive", "fidelity.refine_subrays": 0},
        }.items()
    }
    count = {k: r.detection.p_detect.sum() for k, r in runs.items()}
    assert abs(count["interactive"] / count["reference"] - 1) < 1e-4
    assert abs(count["centres"] / count["reference"] - 1) > 0.01
    rays = runs["interactive"].rays
    corner_lit = rays.corner_directions[:, 2] >= np.cos(scene.illumination_angle_rad / 2)
    crossed = simcore.geometry.straddles(corner_lit.reshape(rays.pixels + 1, -1))
    assert set(np.flatnonzero(crossed)) <= set(runs["interactive"].hits.refined_pixels.tolist())
