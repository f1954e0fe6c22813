"""Exports read back: binary PLY and LAS 1.4 point clouds, NPZ and HDF5 waveform cubes.

One 64 x 64 frame of the MRO (module fixture) feeds every round trip; the LAS tests also use a
synthetic cloud at 100 km to check the 0.1 mm coordinate scale where it matters.
"""

from __future__ import annotations

import laspy
import numpy as np
import pytest

import simcore
from simcore import io
from simcore.pointcloud import ATTRIBUTES, GROUND_TRUTH, PointCloud

HALF_STEP_M = io.LAS_SCALE_M / 2  # worst rounding of a LAS coordinate at the 0.1 mm scale
FLOAT_SLACK_M = 1e-9  # double rounding of (x - offset) / scale at 100 km is ~1e-11 m
COMMENTS = ("lmapd-sim point cloud, sensor frame", "target MRO; 3D model: NASA/JPL-Caltech")


@pytest.fixture(scope="module")
def result():
    return simcore.simulate(pixels=64, overrides={"fidelity.subrays": 1})


def assert_same_attributes(a: PointCloud, b: PointCloud) -> None:
    for name, dtype in ATTRIBUTES:
        assert b.attributes[name].dtype == dtype, name
        np.testing.assert_array_equal(b.attributes[name], a.attributes[name], err_msg=name)


def far_cloud(distance_m: float, n: int = 500, seed: int = 7) -> PointCloud:
    """A synthetic cloud around (0, 0, distance_m) with a few outliers, odd sub-mm coordinates."""
    rng = np.random.default_rng(seed)
    points = rng.uniform(-8.0, 8.0, (n, 3)) + [0.0, 0.0, distance_m]
    outlier = rng.random(n) < 0.1
    attrs = {
        "row": rng.integers(0, 256, n).astype(np.int32),
        "col": rng.integers(0, 256, n).astype(np.int32),
        "range_m": np.linalg.norm(points, axis=1),
        "intensity_w": np.where(outlier, 0.0, rng.uniform(1e-9, 1e-6, n)),
        "snr": np.where(outlier, 0.0, rng.uniform(1.0, 500.0, n)),
        "material_id": np.where(outlier, -1, rng.integers(0, 9, n)).astype(np.int32),
        "facet_id": np.where(outlier, -1, rng.integers(0, 10**6, n)).astype(np.int32),
        "is_outlier": outlier,
    }
    return PointCloud(points=points, attributes=attrs)


def test_ply_reads_back_equal_with_its_comments(tmp_path, result):
    path = tmp_path / "c.ply"
    io.write_cloud(path, result.cloud, COMMENTS)
    back = io.read_cloud(path)
    np.testing.assert_array_equal(back.points, result.points)
    assert_same_attributes(result.cloud, back)
    assert io.read_cloud_comments(path) == COMMENTS


def test_las_reads_back_equal_within_half_a_scale_step(tmp_path, result):
    path = tmp_path / "c.las"
    io.write_cloud(path, result.cloud, COMMENTS)
    back = io.read_cloud(path)
    assert len(back) == len(result.cloud) > 100
    assert np.abs(back.points - result.points).max() <= HALF_STEP_M + FLOAT_SLACK_M
    assert_same_attributes(result.cloud, back)
    assert io.read_cloud_comments(path) == COMMENTS


def test_las_and_ply_read_back_the_same_cloud(tmp_path, result):
    io.write_cloud(tmp_path / "c.ply", result.cloud)
    io.write_cloud(tmp_path / "c.las", result.cloud)
    ply, las = io.read_cloud(tmp_path / "c.ply"), io.read_cloud(tmp_path / "c.las")
    assert_same_attributes(ply, las)
    assert np.abs(ply.points - las.points).max() <= HALF_STEP_M + FLOAT_SLACK_M


def test_a_frame_at_100_km_keeps_a_tenth_of_a_millimetre(tmp_path):
    cloud = far_cloud(100e3)
    path = tmp_path / "far.las"
    io.write_las(path, cloud)
    header = laspy.read(str(path)).header
    np.testing.assert_array_equal(header.scales, [io.LAS_SCALE_M] * 3)
    back = io.read_las(path)
    assert np.abs(back.points - cloud.points).max() <= HALF_STEP_M + FLOAT_SLACK_M
    assert_same_attributes(cloud, back)


def test_a_cloud_beyond_the_int32_reach_gets_a_coarser_power_of_ten(tmp_path):
    cloud = far_cloud(0.0, n=20)
    points = cloud.points.copy()
    points[0, 2], points[1, 2] = -300e3, 300e3  # 300 km from the centre: 0.1 mm cannot reach
    cloud = PointCloud(points=points, attributes=cloud.attributes)
    io.write_las(tmp_path / "wide.las", cloud)
    scale = laspy.read(str(tmp_path / "wide.las")).header.scales[0]
    assert scale == pytest.approx(1e-3)
    back = io.read_las(tmp_path / "wide.las")
    assert np.abs(back.points - cloud.points).max() <= scale / 2 + FLOAT_SLACK_M


def test_the_las_header_is_version_1_4_format_6_with_extra_dimensions(tmp_path, result):
    path = tmp_path / "c.las"
    io.write_las(path, result.cloud, COMMENTS)
    las = laspy.read(str(path))
    h = las.header
    assert (str(h.version), h.point_format.id) == ("1.4", 6)
    assert h.system_identifier == "lmapd-sim simulation"
    assert h.generating_software == f"lmapd-sim {simcore.__version__}"
    assert h.global_encoding.wkt
    assert set(las.point_format.extra_dimension_names) == {
        n for n, _ in (*ATTRIBUTES, *GROUND_TRUTH)
    }
    assert any("NASA/JPL-Caltech" in line for line in io.read_cloud_comments(path))


def test_the_ground_truth_travels_in_ply_and_las_with_units_in_the_las_descriptions(
    tmp_path, result
):
    described = {}
    for suffix in ("ply", "las"):
        path = tmp_path / f"truth.{suffix}"
        io.write_cloud(path, result.cloud)
        back = io.read_cloud(path)
        for name, dtype in GROUND_TRUTH:
            want = np.asarray(result.attributes[name])
            assert np.array_equal(back.attributes[name], want, equal_nan=dtype is not np.bool_)
        if suffix == "las":
            described = {
                d.name: d.description for d in laspy.read(str(path)).point_format.extra_dimensions
            }
    assert "[m]" in described["true_range_m"] and "[m]" in described["range_error_m"]
    assert "[deg]" in described["incidence_deg"]


def test_las_classes_outliers_as_noise_and_target_points_as_class_1(tmp_path):
    cloud = far_cloud(500.0)
    io.write_las(tmp_path / "c.las", cloud)
    las = laspy.read(str(tmp_path / "c.las"))
    outlier = cloud.attributes["is_outlier"]
    assert outlier.any() and (~outlier).any()
    np.testing.assert_array_equal(
        np.asarray(las.classification), np.where(outlier, io.LAS_CLASS_OUTLIER, 1)
    )
    intensity = np.asarray(las.intensity)
    assert intensity.max() == 65535 and (intensity[outlier] == 0).all()
    assert (np.asarray(las.return_number) == 1).all()


def test_an_empty_cloud_round_trips(tmp_path):
    empty = PointCloud(
        points=np.zeros((0, 3)),
        attributes={name: np.zeros(0, dtype=dtype) for name, dtype in ATTRIBUTES},
    )
    for suffix in io.CLOUD_SUFFIXES:
        io.write_cloud(tmp_path / f"e{suffix}", empty)
        back = io.read_cloud(tmp_path / f"e{suffix}")
        assert len(back) == 0
        assert_same_attributes(empty, back)


@pytest.mark.parametrize("suffix", io.WAVEFORM_SUFFIXES)
def test_the_waveform_cube_reads_back_equal(tmp_path, result, suffix):
    path = tmp_path / f"w{suffix}"
    io.write_waveforms(path, result)
    cube, back = io.waveform_cube(result), io.read_waveforms(path)
    assert set(back) == set(cube)
    for name, value in cube.items():
        assert np.asarray(back[name]).dtype == np.asarray(value).dtype, name
        np.testing.assert_array_equal(back[name], value, err_msg=name)
    n, length = cube["power_w"].shape
    assert n == len(result.echo.pixel) and length > 1


def test_unsupported_suffixes_are_refused_and_nothing_is_written(tmp_path, result):
    with pytest.raises(ValueError, match="unsupported point cloud format; use .ply or .las"):
        io.write_cloud(tmp_path / "c.xyz", result.cloud)
    with pytest.raises(ValueError, match="unsupported waveform format"):
        io.write_waveforms(tmp_path / "w.csv", result)
    assert list(tmp_path.iterdir()) == []


def test_a_foreign_las_is_refused_with_the_missing_dimensions(tmp_path):
    las = laspy.LasData(laspy.LasHeader(point_format=6, version="1.4"))
    las.x = las.y = las.z = np.zeros(2)
    las.write(str(tmp_path / "other.las"))
    with pytest.raises(ValueError, match="not an lmapd-sim LAS, no dimension row"):
        io.read_cloud(tmp_path / "other.las")


@pytest.mark.parametrize("suffix", [".ply", ".las"])
def test_a_receivers_own_attributes_are_written_and_read_back(tmp_path, suffix):
    """The Geiger-mode array's extra per-point attributes (counts, signal_pe) go into PLY and LAS
    beside the shared ones and come back exactly."""
    result = simcore.simulate(
        overrides={"pixels": 32, "fidelity.subrays": 1, "receiver.kind": "gm_apd"}
    )
    assert {"counts", "signal_pe"} <= set(result.cloud.attributes) and len(result.cloud) > 0
    path = tmp_path / f"gm{suffix}"
    io.write_cloud(path, result.cloud)
    back = io.read_cloud(path)
    assert set(back.attributes) == set(result.cloud.attributes)
    for name in ("counts", "signal_pe"):
        assert np.array_equal(back.attributes[name], result.cloud.attributes[name])
