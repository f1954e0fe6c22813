"""Ground truth for every point and the imaging-quality metrics (simcore.pointcloud.ground_truth,
simcore.quality), against closed forms first: a plate at normal incidence under a flat-top beam,
the visible cap of a sphere, and a mesh with degenerate faces."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate
from scipy.spatial import cKDTree

import simcore
from simcore import quality
from simcore.pointcloud import pixel_surfaces
from simcore.scene import Scene, SceneError, with_overrides

DISTANCE_M = 100.0
PLATE_M = 2.0  # side of the calibration plate
LIT_RADIUS_M = 0.6  # the flat-top beam's disc on the plate: tan(theta / 2) * distance
THETA_ILL_RAD = 2.0 * math.atan(LIT_RADIUS_M / DISTANCE_M)
FOV_RAD = 0.03
PIXELS = 128

PLATE = {
    "target.mesh": "plate",
    "target.size_m": PLATE_M,
    "pose.distance_m": DISTANCE_M,
    "detector.pixels": PIXELS,
    "receive.fov_rad": FOV_RAD,
    "transmit.illumination": "flat_top",
    "laser.divergence_rad": THETA_ILL_RAD,
    "transmit.beam_expansion_ratio": 1.0,
    "seed": 3,
}


@pytest.fixture(scope="module")
def plate():
    """The plate frame, and the same frame's figures at tau = 5 range sigmas."""
    result = simcore.simulate(with_overrides(Scene(), PLATE))
    d = result.detection
    sigma_m = float(np.median(d.range_sigma_m[d.detected]))
    tau_m = 5.0 * sigma_m
    at_tau = simcore.simulate(with_overrides(Scene(), {**PLATE, "quality.tau_m": tau_m}))
    return result, at_tau, sigma_m, tau_m


def test_a_plate_at_normal_incidence_has_true_ranges_of_distance_over_cos(plate):
    result = plate[0]
    attrs = result.attributes
    target = ~attrs["is_outlier"]
    pixel = attrs["row"][target] * PIXELS + attrs["col"][target]
    u = result.rays.pixel_directions[pixel]
    true_m = attrs["true_range_m"][target]
    # the plate is the plane z = distance: a line of sight u meets it at distance / u_z; a
    # pixel whose four sub-rays are all lit has their mean range, equal to it in the second
    # order (below a micrometre); on the rim of the lit disc, the lit sub-rays' ranges
    weights = result.echo.weights[np.searchsorted(result.echo.pixel, pixel)]
    full = np.all(weights > 0, axis=1)
    assert full.mean() > 0.8
    assert np.abs(true_m[full] - DISTANCE_M / u[full, 2]).max() < 1e-6
    subray_m = result.hits.range_m[pixel]
    assert np.all((true_m >= subray_m.min(axis=1) - 1e-9) & (true_m <= subray_m.max(axis=1) + 1e-9))
    assert np.array_equal(
        attrs["range_error_m"][target], attrs["range_m"][target] - attrs["true_range_m"][target]
    )
    # the incidence is the angle of the line of sight off the plate's normal, the boresight
    want_deg = np.degrees(np.arccos(u[:, 2]))
    assert np.abs(attrs["incidence_deg"][target] - want_deg).max() < 0.3  # a sub-ray's, not u's
    assert set(attrs["part_id"][target]) == {0}


def test_false_alarms_have_no_truth_and_are_outliers(plate):
    attrs = plate[0].attributes
    false = attrs["is_outlier"]
    assert false.any()
    assert np.all(attrs["part_id"][false] == -1) and np.all(attrs["outlier"][false])
    for name in ("true_range_m", "range_error_m", "incidence_deg"):
        assert np.all(np.isnan(attrs[name][false]))


def test_the_plate_is_imaged_with_precision_one_and_no_bias_at_five_sigma(plate):
    _, result, sigma_m, tau_m = plate
    q = result.quality
    n = int(np.count_nonzero(~result.attributes["is_outlier"]))
    # P(|error| > 5 sigma) = 5.7e-7 per point: with ~2,000 points none is expected
    assert q["precision"] == 1.0
    # the median of n normal errors has standard error sqrt(pi / 2) sigma / sqrt(n)
    assert abs(q["range_bias_m"]) <= 4.0 * math.sqrt(math.pi / 2.0) * sigma_m / math.sqrt(n)
    assert q["range_rmse_m"] == pytest.approx(sigma_m, rel=0.1)
    assert q["tau_m"] == tau_m and q["seen_area_m2"] == pytest.approx(PLATE_M**2, rel=1e-9)


def test_the_plate_recall_is_the_lit_share_within_tau_and_a_pixel(plate):
    _, result, _, tau_m = plate
    recall = result.quality["recall"]
    pitch_m = DISTANCE_M * 2 * math.tan(FOV_RAD / 2) / PIXELS  # a pixel's footprint
    assert pitch_m < tau_m  # the lit disc is then covered: no gaps between points
    lit_share = math.pi * LIT_RADIUS_M**2 / PLATE_M**2
    grown = math.pi * (LIT_RADIUS_M + tau_m + pitch_m) ** 2 / PLATE_M**2
    assert lit_share <= recall <= grown


def test_recall_agrees_with_an_independent_grid_integration(plate):
    """The sampler (random, by area) against a regular 400 x 400 grid over the plate."""
    _, result, _, tau_m = plate
    target = ~result.attributes["is_outlier"]
    pose = result.hits.pose
    points_t = quality.to_target_frame(result.points[target], pose)
    g = (np.arange(400) + 0.5) / 400 * PLATE_M - PLATE_M / 2
    gx, gy = np.meshgrid(g, g)
    grid_s = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, DISTANCE_M)], axis=1)
    grid_t = quality.to_target_frame(grid_s, pose)  # the plate's surface, in its own frame
    d_m, _ = cKDTree(points_t).query(grid_t)
    want = float(np.mean(d_m <= tau_m))
    n = result.quality["n_surface_samples"]
    se = math.sqrt(want * (1 - want) / n)
    assert abs(result.quality["recall"] - want) <= 4 * se + 1 / 400  # the grid's own step


SPHERE_RADIUS_M = 1.0
SPHERE_DISTANCE_M = 20.0


def test_the_seen_surface_of_a_sphere_is_its_visible_cap():
    scene = with_overrides(
        Scene(),
        {
            "target.mesh": "sphere",
            "target.size_m": 2 * SPHERE_RADIUS_M,
            "pose.distance_m": SPHERE_DISTANCE_M,
            "detector.pixels": 96,
            "receive.fov_rad": 0.12,
            "transmit.illumination": "flat_top",
            "laser.divergence_rad": 0.12,
            "transmit.beam_expansion_ratio": 1.0,
        },
    )
    result = simcore.simulate(scene)
    q = result.quality
    # the cap seen from distance D: 2 pi R^2 (1 - R / D); the 96-ring polyhedron's area is
    # within 0.1 % of the sphere's, and the seen share is a binomial proportion
    cap_m2 = 2 * math.pi * SPHERE_RADIUS_M**2 * (1 - SPHERE_RADIUS_M / SPHERE_DISTANCE_M)
    facets_m2 = q["seen_area_m2"] / (q["n_surface_samples"] / quality.SURFACE_SAMPLES)
    share = cap_m2 / facets_m2
    se_m2 = facets_m2 * math.sqrt(share * (1 - share) / quality.SURFACE_SAMPLES)
    assert abs(q["seen_area_m2"] - cap_m2) <= 4 * se_m2 + 1e-3 * cap_m2
    assert result.summary(quality=False)["p_detect_mean"] > 0.999 and q["precision"] > 0.99
    # recall against the exact sphere sampled independently: uniform directions, kept where
    # the lidar sees them (p . o > R^2 for the lidar at o), their distance to the nearest point
    rng = np.random.default_rng(11)
    n = 100_000
    v = rng.standard_normal((n, 3))
    on_sphere = SPHERE_RADIUS_M * v / np.linalg.norm(v, axis=1)[:, None]
    lidar_t = -result.hits.pose.rotation.T @ result.hits.pose.translation_m
    visible = on_sphere[on_sphere @ lidar_t > SPHERE_RADIUS_M**2]
    target = ~result.attributes["is_outlier"]
    points_t = quality.to_target_frame(result.points[target], result.hits.pose)
    d_m, _ = cKDTree(points_t).query(visible)
    want = float(np.mean(d_m <= q["tau_m"]))
    se = math.sqrt(want * (1 - want) * (1 / len(visible) + 1 / q["n_surface_samples"]))
    # the 96-ring polyhedron lies within R (1 - cos(pi / 96)) = 0.5 mm of the sphere: a slack
    assert abs(q["recall"] - want) <= 4 * se + 0.005


def test_parts_of_points_are_their_facets_parts_and_add_up(mro_frame):
    result = mro_frame
    attrs = result.attributes
    target = ~attrs["is_outlier"]
    q = result.quality
    assert sum(p["n_points"] for p in q["parts"]) == int(target.sum())
    # a pixel that sees one surface: its point's part is its strongest facet's
    e = result.echo
    lit = np.searchsorted(e.pixel, attrs["row"][target] * result.pixels + attrs["col"][target])
    _, weight = pixel_surfaces(e.arrivals_s[lit], e.weights[lit], 1e-9)
    single = np.count_nonzero(weight > 0, axis=1) == 1
    face_part = np.asarray(result.target.face_part)
    part = attrs["part_id"][target][single]
    assert np.mean(part == face_part[attrs["facet_id"][target][single]]) > 0.99
    for row in q["parts"]:
        assert 0.0 <= row["precision"] <= 1.0 and 0.0 <= row["recall"] <= 1.0


@pytest.fixture(scope="module")
def mro_frame():
    return simcore.simulate(pixels=96)


def test_every_quality_figure_of_the_paper_scene_is_a_finite_number(mro_frame):
    q = mro_frame.quality
    for key, value in q.items():
        if key != "parts":
            assert isinstance(value, (int, float)) and math.isfinite(value), key
    assert 0 < q["recall"] < 1 and q["precision"] > 0.95
    assert q["f_score"] == pytest.approx(
        2 * q["precision"] * q["recall"] / (q["precision"] + q["recall"])
    )


def test_a_mesh_with_zero_area_faces_gives_finite_figures(tmp_path):
    path = tmp_path / "degenerate.obj"
    lines = [
        "v -1 -1 0",
        "v 1 -1 0",
        "v 1 1 0",
        "v -1 1 0",
        "v 0 0 0",
        "v 0.5 0.5 0",
        "f 1 2 3",
        "f 1 3 4",
        "f 5 5 5",  # a point
        "f 1 5 3",  # a sliver on the diagonal: three collinear vertices
        "f 2 2 6",
    ]
    path.write_text("\n".join(lines) + "\n")
    scene = with_overrides(
        Scene(), {**PLATE, "target.mesh": str(path), "target.size_m": 0.0, "detector.pixels": 48}
    )
    result = simcore.simulate(scene)
    q = result.quality
    assert len(result.cloud) > 0
    for key, value in q.items():
        if key != "parts":
            assert value is None or math.isfinite(value), key
    assert q["precision"] > 0.99 and q["seen_area_m2"] == pytest.approx(4.0, rel=1e-9)


def test_the_surfaces_of_a_pixel_split_where_elements_are_a_pulse_apart():
    arrivals = np.array([[1.0, 1.1, 5.0, 0.0], [2.0, 2.0, 2.0, 2.0]]) * 1e-9
    weights = np.array([[1.0, 3.0, 2.0, 0.0], [1.0, 1.0, 1.0, 1.0]])
    delay, weight = pixel_surfaces(arrivals, weights, gap_s=1e-9)
    assert delay[0, 0] == pytest.approx((1.0 * 1.0 + 3.0 * 1.1) / 4.0 * 1e-9)
    assert delay[0, 1] == pytest.approx(5e-9) and np.isnan(delay[0, 2:]).all()
    assert list(weight[0]) == [4.0, 2.0, 0.0, 0.0] and delay[1, 0] == pytest.approx(2e-9)


@pytest.mark.parametrize("bad", [0.0, -0.01, float("nan"), float("inf"), "5 cm"])
def test_a_bad_tau_is_refused_with_one_message_naming_the_key(bad):
    with pytest.raises(SceneError, match=r"quality\.tau_m"):
        with_overrides(Scene(), {"quality.tau_m": bad})


def test_quality_is_computed_only_when_asked_for():
    pipeline = simcore.Pipeline()
    result = pipeline.run(with_overrides(Scene(), {"detector.pixels": 32}))
    assert "quality" not in result.timings_s and "quality" not in result.extras
    assert "quality" not in result.summary(quality=False)
    with_quality = pipeline.run(result.scene, extras=("quality",))
    assert with_quality.extras["quality"] == result.quality
    with pytest.raises(ValueError, match="optional stage"):
        pipeline.run(result.scene, extras=("colour",))


def test_the_geiger_mode_first_photon_cloud_carries_the_ground_truth():
    from simcore import pointcloud
    from simcore.pointcloud import GROUND_TRUTH

    result = simcore.simulate(
        with_overrides(Scene(), {"receiver.kind": "gm_apd", "detector.pixels": 24})
    )
    cloud = pointcloud.first_photon_cloud(result)
    attrs = cloud.attributes
    assert {name for name, _ in GROUND_TRUTH} <= set(attrs)
    echo = ~attrs["is_outlier"]
    assert echo.any()
    assert np.isfinite(attrs["true_range_m"][echo]).all()
    assert np.array_equal(
        attrs["range_error_m"][echo], attrs["range_m"][echo] - attrs["true_range_m"][echo]
    )
    assert np.isnan(attrs["true_range_m"][~echo]).all() and attrs["outlier"][~echo].all()


def _calibration_scene(mesh: str, size_m: float, pixels: int, **extra) -> Scene:
    return with_overrides(
        Scene(),
        {
            "target.mesh": mesh,
            "target.size_m": size_m,
            "pose.distance_m": 20.0,
            "detector.pixels": pixels,
            "receive.fov_rad": 0.12,
            "transmit.illumination": "flat_top",
            "laser.divergence_rad": 0.12,
            "transmit.beam_expansion_ratio": 1.0,
            **extra,
        },
    )


def test_the_projected_recall_is_smooth_where_a_face_turns_into_view_and_the_plain_recall_jumps():
    # the lidar level with a cube's top face: a fiftieth of a degree of pitch either way hides it
    # or shows it edge-on, its whole square metre with no pixel on it
    scene = _calibration_scene("cube", 1.0, 32, **{"pose.offset_y_m": 0.5})
    pipe = simcore.Pipeline()
    below, above = (pipe.run(with_overrides(scene, pitch_deg=p)).quality for p in (-0.02, 0.02))
    assert above["seen_area_m2"] == pytest.approx(2 * below["seen_area_m2"], rel=0.02)
    assert above["recall"] < 0.6 * below["recall"]  # the new face's area counts, unsampled
    # weighted by |cos incidence| the new face weighs nothing: the front face's samples decide,
    # about a sixth of the cube's (binomial sd of each, 4 sd of their difference)
    n_front = quality.SURFACE_SAMPLES / 6
    r = below["recall_projected"]
    assert abs(above["recall_projected"] - r) <= 4 * math.sqrt(2 * r * (1 - r) / n_front)
    assert above["seen_projected_area_m2"] == pytest.approx(
        below["seen_projected_area_m2"], rel=0.01
    )
    # the ideal lidar with these pixels is as far from the plain recall's 1: the cap says so
    assert above["recall_cap"] < 0.6 and above["recall_projected_cap"] > 0.99
    assert above["recall_sd"] == pytest.approx(
        math.sqrt(above["recall"] * (1 - above["recall"]) / above["n_surface_samples"])
    )


def test_a_spheres_projected_seen_area_is_the_integral_of_cos_incidence_over_its_cap():
    radius_m, distance_m = 1.0, 20.0
    scene = _calibration_scene("sphere", 2 * radius_m, 32)
    q = simcore.simulate(scene).quality

    def cos_incidence_area(psi):  # the lidar at D from the centre, a point at angle psi from it
        r = math.sqrt(distance_m**2 + radius_m**2 - 2 * distance_m * radius_m * math.cos(psi))
        cos_theta = (distance_m * math.cos(psi) - radius_m) / r
        return cos_theta * 2 * math.pi * radius_m**2 * math.sin(psi)

    expected_m2, _ = integrate.quad(cos_incidence_area, 0.0, math.acos(radius_m / distance_m))
    area_m2 = 4 * math.pi * radius_m**2  # the polyhedron's is within 0.1 % of it
    # the estimate: area x mean of w 1_seen over the samples; var <= E[w 1_seen] (w <= 1)
    sd_m2 = area_m2 * math.sqrt(expected_m2 / area_m2 / quality.SURFACE_SAMPLES)
    assert abs(q["seen_projected_area_m2"] - expected_m2) <= 4 * sd_m2 + 1e-3 * expected_m2


def test_an_ideal_lidars_recall_of_a_face_on_plate_is_its_pixel_lattices_cover():
    pixels, tau_m = 40, 0.02  # a footprint of 6 cm, more than 2 tau: the discs do not overlap
    scene = _calibration_scene("plate", 1.0, pixels, **{"quality.tau_m": tau_m})
    result = simcore.simulate(scene)
    q = result.quality
    # the lattice: each pixel's centre ray on the plate's plane, z = D (face-on), inside it
    d = result.rays.pixel_directions
    lattice = d[:, :2] * (20.0 / d[:, 2])[:, None]
    lattice = lattice[np.all(np.abs(lattice) <= 0.5, axis=1)]
    g = (np.arange(600) + 0.5) / 600 - 0.5  # the plate on a fine grid: the share within tau
    grid = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    near, _ = cKDTree(lattice).query(grid, k=1)
    covered = float(np.mean(near <= tau_m))
    assert covered == pytest.approx(math.pi * tau_m**2 / 0.06**2, rel=0.15)  # a lattice's discs
    n = q["n_surface_samples"]
    sd = math.sqrt(covered * (1 - covered) / n)
    assert abs(q["recall_cap"] - covered) <= 4 * sd + 2 / 600
    assert q["recall_projected_cap"] == pytest.approx(q["recall_cap"], abs=4 * sd)


# ----------------------------------------------------------------------------------------------
# issue 43, item 4: figures named for what they are
# ----------------------------------------------------------------------------------------------
def _shifted_cloud(result, shift_m: float):
    """The frame's cloud with every target point moved ``shift_m`` along its own line of sight
    and its ground-truth error set to 0: what a mixed pixel's point floating between two depths
    looks like against the energy-weighted truth of its surface group."""
    from simcore.pointcloud import PointCloud

    attrs = dict(result.cloud.attributes)
    target = ~np.asarray(attrs["is_outlier"], dtype=bool)
    points = result.cloud.points.copy()
    r = np.linalg.norm(points[target], axis=1)
    points[target] *= ((r + shift_m) / r)[:, None]
    error = attrs["range_error_m"].copy()
    error[target] = 0.0
    attrs["range_error_m"] = error
    outlier = attrs["outlier"].copy()
    outlier[target] = False
    attrs["outlier"] = outlier
    return PointCloud(points=points, attributes=attrs), target


def test_the_range_rmse_is_measured_along_each_points_line_of_sight(plate):
    result = plate[0]
    shift_m = 0.3
    cloud, target = _shifted_cloud(result, shift_m)
    q = quality.quality_metrics(cloud, result.caster, result.hits, FOV_RAD, 0.05, seed=3)
    # against the plane z = distance each point lies its own measured error + 0.3 m behind it;
    # the frame's own errors (sd sigma) add in quadrature to within their sample's spread
    errors = result.attributes["range_error_m"][~result.attributes["is_outlier"]]
    want = math.sqrt(np.mean((errors + shift_m) ** 2))
    assert q["range_rmse_m"] == pytest.approx(want, abs=1e-4)
    assert q["range_rmse_surface_m"] == 0.0  # the surface group's truth sees no error


def test_the_distance_to_mesh_figures_are_the_points_exact_distances(plate):
    result = plate[0]
    cloud, target = _shifted_cloud(result, 0.3)
    q = quality.quality_metrics(cloud, result.caster, result.hits, FOV_RAD, 0.05, seed=3)
    # the plate is the plane z = distance (sensor frame, boresight on its normal): a point's
    # distance to it is |z - distance| wherever it lies over the plate, as all lit points do
    d_m = np.abs(cloud.points[target, 2] - DISTANCE_M)
    assert q["distance_to_mesh_median_m"] == pytest.approx(float(np.median(d_m)), abs=1e-6)
    assert q["distance_to_mesh_p95_m"] == pytest.approx(float(np.percentile(d_m, 95)), abs=1e-6)


def test_the_two_outlier_shares_each_count_over_their_own_points(plate):
    result = plate[0]
    attrs = result.attributes
    false = attrs["is_outlier"]
    far = attrs["outlier"] & ~false
    q = result.quality
    assert q["false_alarm_fraction"] == np.count_nonzero(false) / len(false)
    assert q["target_outlier_fraction"] == np.count_nonzero(far) / np.count_nonzero(~false)
    assert "outlier_fraction" not in q
