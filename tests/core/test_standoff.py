"""The lidar's stand-off: a pose that puts it closer to the surface it sees than the echo model
holds for (MIN_STANDOFF_M), or inside a closed target, is refused with one message naming
distance_m (the far field's 1 / R^2 grows without bound at the surface: a 0.35 J pulse at a
few millimetres overflowed the waveform Monte Carlo to inf). Closed forms: the calibration
sphere (radius 1 m) at distance d shows its nearest point at d - 1 m on the boresight."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import simcore
from simcore.geometry.stages import MIN_STANDOFF_M
from simcore.scene import SceneError, with_overrides
from simcore.target_mesh import TargetMesh

RADIUS_M = 1.0  # the calibration sphere's (2 m across)


def sphere_at(distance_m: float, **more) -> simcore.Result:
    scene = with_overrides(
        simcore.load_scene(),
        {"target.mesh": "sphere", "distance_m": distance_m, "pixels": 32, **more},
    )
    return simcore.Pipeline().run(scene)


def test_the_sphere_runs_just_past_the_stand_off_and_its_nearest_hit_is_d_minus_r():
    d = RADIUS_M + MIN_STANDOFF_M + 0.01
    result = sphere_at(d)
    nearest = np.nanmin(np.where(np.isfinite(result.hits.range_m), result.hits.range_m, np.nan))
    # the nearest rays are a half pixel off the boresight (0.03 rad / 64): r theta^2 / 2 = 0.1 um
    assert d - RADIUS_M - 1e-3 < nearest < d - RADIUS_M + 1e-3
    assert result.summary()["n_target_points"] > 0


@pytest.mark.parametrize(
    "distance_m", [RADIUS_M + MIN_STANDOFF_M - 0.01, RADIUS_M, RADIUS_M + 1e-6]
)
def test_closer_than_the_stand_off_is_refused_naming_distance_m(distance_m):
    with pytest.raises(SceneError) as refused:
        sphere_at(distance_m)
    text = str(refused.value)
    assert text.startswith("distance_m:") and "closer than the 0.3 m" in text and "\n" not in text


@pytest.mark.parametrize("distance_m", [0.05, 0.3, 0.69])
def test_inside_a_closed_target_is_refused_naming_distance_m(distance_m):
    """From within, every first hit is on the inner side of its face (0.69 m: 0.31 m from the
    wall ahead, past the stand-off)."""
    with pytest.raises(SceneError, match=r"^distance_m: .* is inside the target"):
        sphere_at(distance_m)


def test_an_open_plate_seen_from_behind_at_the_stand_off_is_not_inside(plate_scene):
    scene = plate_scene(size_m=4.0, **{"distance_m": MIN_STANDOFF_M + 0.01, "pitch_deg": 180.0})
    result = simcore.Pipeline().run(scene)
    assert np.isfinite(result.hits.range_m).any()


def test_closed_means_every_edge_twice_in_opposite_directions():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    assert TargetMesh(sphere.vertices, sphere.faces).closed
    flipped = sphere.faces.copy()
    flipped[0] = flipped[0][::-1]  # one face wound the other way
    assert not TargetMesh(sphere.vertices, flipped).closed
    open_cap = sphere.faces[1:]
    assert not TargetMesh(sphere.vertices, open_cap).closed
    box = trimesh.creation.box()
    split = box.vertices[box.faces].reshape(-1, 3)  # a vertex per corner of each triangle
    assert not TargetMesh(split, np.arange(len(split)).reshape(-1, 3)).closed
    assert TargetMesh(box.vertices, box.faces).closed


def test_a_joule_pulse_near_the_stand_off_runs_the_photon_model_without_overflow():
    """The combination the property test found (0.35 J at 1 m from a 1 m sphere), moved out
    to the stand-off: primaries per sample past numpy's Poisson limit, finite throughout."""
    with np.errstate(all="raise"):
        result = sphere_at(
            RADIUS_M + MIN_STANDOFF_M + 0.01,
            **{"fidelity.noise_model": "photon", "pulse_energy_j": 0.35, "pixels": 18},
        )
    summary = result.summary()
    assert summary["n_target_points"] > 0
    assert np.all(np.isfinite(np.asarray(result.cloud.points)))
