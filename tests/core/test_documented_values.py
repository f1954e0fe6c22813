"""Issue 43, item 1: every documented value of the pulse width and the bandwidth runs or is
refused in one line before the work that would take minutes.

The reference pulse's CFD stop (the t*_ref every Monte Carlo stop is measured against) is
checked over pulse width x bandwidth at and between their documented edges, wherever the
statistical model's gross-error table would be drawn at all (its cost check passes); the
frame-level refusals at the pixel edges run on a plate, whose echo stage takes well under a
second at these sizes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import simcore
from simcore.pulse import A_FWHM, cfd_delay_s, default_time_step_s, pulse_shape
from simcore.receivers.lm_apd import gross_errors
from simcore.receivers.lm_apd.montecarlo.currents import band_limit
from simcore.receivers.lm_apd.montecarlo.discriminator import (
    REFERENCE_PHASES,
    discriminate,
    raw_end_s,
)
from simcore.scene import SceneError, with_overrides

TAU_RANGE_S = (1e-11, 1e-6)  # laser.pulse_width_s, documented
BANDWIDTH_RANGE_HZ = (1e3, 1e11)  # detector.bandwidth_hz, documented
DEFAULT_TNR = 5.0


def _log_uniform(lo: float, hi: float):
    return st.floats(math.log10(lo), math.log10(hi)).map(lambda x: 10.0**x)


def _reference_stops(tau_s: float, bandwidth_hz: float):
    """The reference pulse through the discriminator as reference_stop_s runs it, its stops
    returned: (stops, phases [s])."""
    shape = pulse_shape(tau_s, A_FWHM, bandwidth_hz)
    dt = default_time_step_s(tau_s, bandwidth_hz)
    band = band_limit(dt, bandwidth_hz)
    t_d = cfd_delay_s(shape, 0.0)
    m = band.half_width
    pre = m + math.ceil(t_d / dt) + 4
    t = dt * (np.arange(pre + math.ceil((raw_end_s(shape) + t_d) / dt) + m + 5) - pre)
    phase = dt * (np.arange(REFERENCE_PHASES) + 0.5) / REFERENCE_PHASES
    x = np.zeros((REFERENCE_PHASES, len(t) + 2 * m), dtype=np.float32)
    x[:, m : m + len(t)] = shape.raw_at(t[None, :] - phase[:, None])
    y = shape.filtered_at(t[None, :] - phase[:, None]).astype(np.float32)
    stops = discriminate(y, dt, 0.5 * float(y.max()), t_d, 0.5, t0_s=t[0], x_padded_a=x, band=band)
    return stops, phase


def _drawn(tau_s: float, bandwidth_hz: float) -> bool:
    """The gross-error table of this pulse and band at the auto step passes its cost check."""
    dt = default_time_step_s(tau_s, bandwidth_hz)
    try:
        gross_errors.check_calibration_cost(tau_s, bandwidth_hz, dt, DEFAULT_TNR)
    except SceneError:
        return False
    return True


@pytest.mark.slow  # 7-10 s with a cold cache (the pulse tables of 18 pulse x band pairs)
@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])  # fmt: skip
@given(tau_s=_log_uniform(*TAU_RANGE_S), bandwidth_hz=_log_uniform(*BANDWIDTH_RANGE_HZ))
@example(tau_s=1e-11, bandwidth_hz=5e9)  # the audit's 10 ps pulse at the band its key advises
@example(tau_s=3e-11, bandwidth_hz=120e6)  # the audit's 30 ps pulse at the default band
@example(tau_s=5e-9, bandwidth_hz=1e6)  # the audit's 1 MHz band
@example(tau_s=1e-6, bandwidth_hz=1e3)  # both lower edges
@example(tau_s=1e-11, bandwidth_hz=1e11)  # both upper edges (refused: no table is drawn)
@example(tau_s=1e-6, bandwidth_hz=1e11)
def test_the_reference_pulse_gives_one_cfd_stop_per_phase_wherever_its_table_is_drawn(
    tau_s, bandwidth_hz
):
    if not _drawn(tau_s, bandwidth_hz):
        with pytest.raises(SceneError, match=r"detector\.bandwidth_hz = .* fidelity\.time_step_s"):
            gross_errors.check_calibration_cost(
                tau_s, bandwidth_hz, default_time_step_s(tau_s, bandwidth_hz), DEFAULT_TNR
            )
        return
    stops, phase = _reference_stops(tau_s, bandwidth_hz)
    assert np.array_equal(stops.row, np.arange(REFERENCE_PHASES))
    assert stops.fired.all()
    # each phase's stop is the same instant of the pulse to within a hundredth of a step
    dt = default_time_step_s(tau_s, bandwidth_hz)
    late = stops.t_s - phase[stops.row]
    assert np.ptp(late) < 0.01 * dt


def test_the_one_megahertz_band_limits_tail_arms_no_second_time():
    """The audit's case: 4 of 16 phases armed again on the tail (h_B of the sampled pulse 0.4 %
    of the peak above the closed-form current); the tail is monotone, so no stop follows."""
    stops, _ = _reference_stops(5e-9, 1e6)
    assert len(stops.t_s) == REFERENCE_PHASES


@pytest.mark.parametrize(
    ("overrides", "named"),
    [
        # the echo windows: 2.4e9 samples at 64 px (48 s in the echo kernel before)
        ({"detector.bandwidth_hz": 1e3, "pixels": 64, "target.size_m": 20.0}, "echo windows"),
        # the gross-error table: 1.7e9 samples (a 0.5 ps step over its 2.5 m gate; past 90 s)
        ({"detector.bandwidth_hz": 1e11, "pixels": 64}, "gross-error table"),
        # a 10 ps pulse at 120 MHz: 1.5e9 samples through 14,107 taps (3 minutes before)
        ({"laser.pulse_width_s": 1e-11, "pixels": 64, "target.mesh": "mro"}, "gross-error table"),
        # a 1 us pulse at 1 kHz: 16,927 taps (465 s before)
        (
            {
                "detector.bandwidth_hz": 1e3,
                "laser.pulse_width_s": 1e-6,
                "pixels": 64,
                "target.size_m": 20.0,
            },
            "gross-error table",
        ),
    ],
)
def test_a_frame_that_would_run_for_minutes_is_refused_in_one_line(overrides, named):
    scene = with_overrides(simcore.load_scene(), {"target.mesh": "plate"} | overrides)
    with pytest.raises(SceneError, match=named) as caught:
        simcore.Pipeline().run(scene)
    text = str(caught.value)
    assert "\n" not in text and "detector.bandwidth_hz" in text


def test_the_lower_bandwidth_edge_runs_with_a_long_pulse_at_one_pixel():
    """B = 1 kHz with a 1 us pulse (auto step 100 ns): one pixel on a plate, above the gross
    errors' SNRs, draws no table (at 64 px, below, it would: refused)."""
    scene = with_overrides(
        simcore.load_scene(),
        {"target.mesh": "plate", "target.size_m": 20.0, "detector.bandwidth_hz": 1e3,
         "laser.pulse_width_s": 1e-6, "pixels": 1},
    )  # fmt: skip
    assert simcore.Pipeline().run(scene).summary()["n_lit_pixels"] == 1


def test_the_photon_noise_model_at_1024_pixels_is_refused_before_any_work():
    scene = with_overrides(simcore.load_scene(), {"fidelity.noise_model": "photon"})
    with pytest.raises(SceneError, match=r"detector\.pixels = 1024 .* photon"):
        with_overrides(scene, {"pixels": 1024})


def test_the_montecarlo_gate_counts_the_band_limits_taps():
    overrides = {"fidelity.noise_model": "montecarlo", "detector.bandwidth_hz": 1e3}
    with pytest.raises(SceneError, match="band limit's taps"):
        with_overrides(simcore.load_scene(), overrides)
