"""The Geiger-mode (single-photon) APD array, ``receiver.kind = "gm_apd"``, by concern:

- :mod:`.frame`: the photon budget, the gate and the frame's expected load (its refusal);
- :mod:`.events`: the avalanches of every pixel and pulse (dead time, jitter, TDC bins,
  afterpulsing, crosstalk); :mod:`.limits`: the chance to be armed, the memory per avalanche;
- :mod:`.histogram`: the sparse per-pixel histogram, its peak windows and centroid estimator;
- :mod:`.response`: the receiver stage; :mod:`.records`: its response and detection records;
- :mod:`.windows`: the peak window, its expected counts, thresholds and predicted P_d;
- :mod:`.detection`: the detection stage; :mod:`.false_points`: the expected false points;
- :mod:`.figures`: the predicted and measured ``gm.*`` figures; :mod:`.counts`: a pixel's
  measured, expected and arriving counts as the app's counts chart draws them;
- :mod:`.pileup` (with :mod:`.expected`, :mod:`.coates`, :mod:`.first_photon`): the range the
  histogram gives at any flux, and the first-photon correction;
- :mod:`.section`: its scene section ``[gm]`` and the rules between its keys.

Here: its declaration, ``RECEIVER`` (:mod:`simcore.plugins.declaration`), which the registry
loads by name; declaring it loads none of the physics above (the steps are named, imported on
first use).

The model: docs/physics.md#geiger-mode, docs/physics.md#gm-pileup.
"""

from __future__ import annotations

from ...plugins.declaration import (
    Attribute,
    Control,
    Figure,
    Receiver,
    Section,
    Series,
    StatsRow,
)
from .section import GeigerMode, check_scene

_HERE = __name__

RECEIVER = Receiver(
    kind="gm_apd",
    doc="Geiger-mode single-photon APD array: photon-counting histograms of gm.pulses pulses",
    section=Section(name="gm", keys=GeigerMode, doc="the Geiger-mode array's parameters"),
    check_scene=check_scene,
    response_reads=f"{_HERE}.response:_response_reads",
    respond=f"{_HERE}.response:respond",
    detection_reads=f"{_HERE}.detection:_detection_reads",
    detect=f"{_HERE}.detection:_detect_with_warnings",
    summary_figures=(
        Figure(
            name="n_false_points_expected",
            unit="1",
            doc="false points expected in the cloud per frame (the scan statistic)",
        ),
        Figure(name="gm.range_bias_m", unit="m", doc="predicted range bias of the estimator"),
        Figure(name="gm.range_sigma_m", unit="m", doc="predicted range scatter of the cloud"),
        Figure(
            name="gm.saturated_pixel_fraction",
            unit="1",
            doc="share of lit pixels with over one photoelectron per pulse (piled up)",
        ),
        Figure(name="gm.signal_pe_median", unit="1", doc="median echo photoelectrons per pulse"),
        Figure(name="gm.frame_pulse_energy_j", unit="J", doc="the frame's attenuated pulse energy"),
        Figure(name="gm.range_error_median_m", unit="m", doc="measured median range error"),
        Figure(name="gm.range_error_sd_m", unit="m", doc="measured range error sd"),
    ),
    point_attributes=(
        Attribute(name="counts", unit="1", doc="counts in the pixel's peak window"),
        Attribute(name="signal_pe", unit="1", doc="mean echo photoelectrons per pulse"),
    ),
    label="Geiger mode",
    short="gm",
    description="Geiger-mode array, {scene[gm][pulses]} pulses",
    # the app's glossary: its own words, and its halves of the shared ones (after the page's)
    glossary=(
        ("TNR", "In Geiger mode it sets the count threshold's false-alarm rate."),
        (
            "SNR",
            "Geiger mode: the count SNR S/√(S+B), the echo's expected counts S in the peak "
            "window over the square root of those plus the background's B, over the frame's "
            "pulses.",
        ),
        (
            "Pile-up",
            "Geiger mode: after an avalanche a pixel is dead for the dead time, so with several "
            "photons per pulse only the earliest are counted; the histogram leans to the echo's "
            "onset and the range comes out short.",
        ),
        (
            "Dead time",
            "Geiger mode: the time after an avalanche during which a pixel cannot fire again "
            "(it is re-armed at each gate).",
        ),
        (
            "Dark count",
            "Geiger mode: an avalanche with no photon (thermal or tunnelling), at the dark count "
            "rate; it looks like a background photon.",
        ),
        (
            "PDE",
            "Photon detection efficiency: the share of the photons reaching a Geiger-mode pixel "
            "that set off an avalanche.",
        ),
        (
            "Pulses per frame",
            "Geiger mode: a frame sums the counts of this many laser pulses into each pixel's "
            "histogram; more pulses, more counts and a longer frame.",
        ),
        (
            "Transmit attenuation",
            "Geiger mode: the pulse energy is cut by this many decibels (10 dB: a tenth) so that "
            "the pixels see under one photoelectron per pulse and do not pile up.",
        ),
        ("Background light", "its photons to the counts (Geiger mode)."),
    ),
    hint="Each pixel counts single photons over the pulses (dead time re-armed at each gate); "
    "click a pixel to see its histogram against the counts expected without dead time. "
    "TNR sets the count threshold's false-alarm rate. The transmit attenuation keeps the "
    "pixels photon-starved (under one photoelectron a pulse): brighter echoes pile up "
    "and range early.",
    controls=(
        Control(
            name="gm_pde",
            key="gm.pde",
            label="Photon detection efficiency",
            unit="",
            lo=0.01,
            hi=1.0,
            step=0.01,
            terms=("PDE",),
        ),
        Control(
            name="gm_dark_count_rate_hz",
            key="gm.dark_count_rate_hz",
            label="Dark count rate",
            unit="Hz",
            lo=1.0,
            hi=1e8,
            step=1.0,
            log_slider=True,
            terms=("Dark count",),
        ),
        Control(
            name="gm_dead_time_ns",
            key="gm.dead_time_s",
            label="Dead time",
            unit="ns",
            lo=1.0,
            hi=1e5,
            step=1.0,
            scale=1e-9,
            log_slider=True,
            terms=("Dead time", "Pile-up"),
        ),
        Control(
            name="gm_pulses",
            key="gm.pulses",
            label="Pulses per frame",
            unit="",
            lo=1,
            hi=1000,
            step=1,
            integer=True,
            terms=("Pulses per frame",),
        ),
        Control(
            name="gm_attenuation_db",
            key="gm.attenuation_db",
            label="Transmit attenuation",
            unit="dB",
            lo=0.0,
            hi=100.0,
            step=1.0,
            terms=("Transmit attenuation", "Pile-up"),
        ),
    ),
    stats_rows=(
        StatsRow(label="Echo photoelectrons / pulse", text="{noise[signal_pe_median]:.3g}"),
        StatsRow(label="Avalanches in the frame", text="{noise[events]:,.0f}"),
    ),
    snr_name="count SNR S/√(S+B)",
    snr_stats_label="Median count SNR S/√(S+B) (frame)",
    threshold_on_snr_axis=False,
    chart="counts",
    counts=f"{_HERE}.counts:frame_counts",
    chart_title="Photon counts of the selected pixels",
    chart_series=(
        Series(style="bars", doc="avalanches counted per time bin over the frame's pulses"),
        Series(
            style="solid step",
            doc="the counts expected from the same pulses (dead time and jitter included)",
        ),
        Series(
            style="dotted",
            doc="the photons arriving without dead time (right axis when larger): where they "
            "part, pile-up",
        ),
        Series(style="top axis", doc="the range c t / 2"),
    ),
    snr_caption="Count SNR S / √(S + B) of the pixels with an echo (the frame's expected "
    "counts in the peak window)",
    frame_load=f"{_HERE}.frame:frame_budget",
    frame_pulses_key="gm.pulses",
    pulses_needed=f"{_HERE}.windows:pulses_needed",
    range_bias_figure="gm.range_bias_m",
    range_sigma_figure="gm.range_sigma_m",
)
