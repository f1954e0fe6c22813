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


def test_a_tilted_plane_needs_no_refinement_inside_its_silhouette(plate_scene):
    res = simcore.Pipeline().run(
        plate_scene(
            size_m=4.0,
            distance_m=300.0,
            azimuth_deg=60.0,
            pixels=64,
            **{"fidelity.subrays": 4, "fidelity.refine_subrays": 64},
        )
    )
    refined = np.zeros(64 * 64, bool)
    refined[res.hits.refined_pixels] = True
    interior = res.hits.base.face.reshape(64, 64, -1).min(axis=2) >= 0  # fully covered pixels
    for _ in range(2):  # two rings in: next to a partly covered pixel the mean range is biased
        inner = np.zeros_like(interior)
        inner[1:-1, 1:-1] = (
            interior[1:-1, 1:-1]
            & interior[:-2, 1:-1]
            & interior[2:, 1:-1]
            & interior[1:-1, :-2]
            & interior[1:-1, 2:]
        )
        interior = inner
    assert interior.sum() > 200
    assert not refined.reshape(64, 64)[interior].any()  # a plane at 60 deg: nothing inside
    assert refined.sum() > 0  # but its silhouette is


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
    fast = pipe.run(step_scene(tmp_path, 65, preset="interactive"))
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
