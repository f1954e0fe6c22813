"""Issue 43, item 1: the CLI fuzz's findings, each on a small frame (16 px, a plate)."""

from __future__ import annotations

import numpy as np
import pytest

import simcore
from simcore.scene import with_overrides


def _summary(overrides: dict) -> dict:
    scene = with_overrides(simcore.load_scene(), {"target.mesh": "plate", "pixels": 16} | overrides)
    return simcore.Pipeline().run(scene).summary()


@pytest.mark.parametrize("gate_m", [1e-30, 1e-300])
def test_a_geiger_mode_gate_shorter_than_one_bin_runs_and_gives_no_point(gate_m):
    summary = _summary({"receiver.kind": "gm_apd", "timing.range_gate_m": gate_m, "gm.pulses": 4})
    assert summary["n_points"] == 0
    assert any("outside the range gate" in line for line in summary["warnings"])


def test_geiger_mode_keys_given_to_the_linear_mode_receiver_are_named_in_a_warning():
    summary = _summary({"gm.pulses": 7, "gm.jitter_s": 1e-9})
    assert (
        "gm.jitter_s, gm.pulses set for receiver.kind = gm_apd: receiver.kind = lm_apd ignores "
        "them" in summary["warnings"]
    )


def test_the_selected_receivers_own_keys_give_no_such_warning():
    summary = _summary({"receiver.kind": "gm_apd", "gm.pulses": 4})
    assert not any("ignores" in line for line in summary.get("warnings", []))


@pytest.mark.parametrize(
    "blinding", [{"gm.dark_count_rate_hz": 1e9}, {"gm.dead_time_s": 1.0, "sun.mode": "manual"}]
)
def test_a_blinded_geiger_mode_pixels_count_snr_is_zero_and_the_summary_says_why(blinding):
    """1e9 Hz of dark counts or a 1 s dead time in sunlight: the echo expects ~1e-85 counts a
    frame (the fuzz's median SNR 1e-68 to 1e-103); an SNR of 0 and the warning that says why."""
    summary = _summary({"receiver.kind": "gm_apd", "gm.pulses": 20} | blinding)
    assert summary["snr_median"] == 0.0
    assert any("keep most lit pixels dead" in line for line in summary["warnings"])


def test_points_beyond_the_targets_reach_are_false_alarms_not_target_points():
    """At the maximum jitter (1 us, 150 m rms) Geiger-mode windows land anywhere in the gate:
    a point more than tau outside the shell of the target's bounding sphere is no point of it."""
    scene = with_overrides(
        simcore.load_scene(),
        {"target.mesh": "plate", "pixels": 16, "receiver.kind": "gm_apd", "gm.jitter_s": 1e-6},
    )
    result = simcore.Pipeline().run(scene)
    attrs = result.attributes
    target = ~attrs["is_outlier"]
    reach_m = result.target.radius_m + scene.quality.tau_m
    centre_m = scene.pose.distance_m
    assert np.all(np.abs(attrs["range_m"][target] - centre_m) <= reach_m)
    assert np.count_nonzero(~target) > 0  # the fuzz's case has such points
    far = ~target & np.isnan(attrs["true_range_m"])
    assert np.array_equal(far, ~target) and np.all(attrs["part_id"][~target] == -1)
    assert result.summary(quality=False)["n_outliers"] == np.count_nonzero(~target)
