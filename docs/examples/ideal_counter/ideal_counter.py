"""An ideal photon counter: a receiver written outside the simulator (docs/receivers.md).

Each pixel counts the echo's photoelectrons of one pulse, with no dead time, no dark counts and
no background: it detects the echo when the count reaches ``counter.threshold_pe`` (P_d is the
Poisson tail) and ranges it at the centroid of the photons' arrival times (Eq. 1's pulse,
Gamma(2, s): a single photon's sd is sqrt(2) s). Its section ``[counter]``, its steps, figures,
point attribute and app controls are all in ``RECEIVER``; it plugs in by the entry point of its
pyproject.toml, or by ``simcore.receivers.register(RECEIVER)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from simcore.receivers import Attribute, Control, Figure, Receiver, Section, StatsRow, register
from simcore.receivers.records import Detection, Outliers, Response
from simcore.scene.fields import key

C, H = 299_792_458.0, 6.62607015e-34  # [m/s], [J s]


@dataclass(frozen=True)
class Counter:
    qe: float = key(0.5, "1", 0.0, 1.0, "photon detection efficiency", lo_open=True)
    threshold_pe: float = key(1.0, "1", 1.0, 1e6, "photoelectrons a pixel needs to detect")


def respond(scene, echo, background) -> Response:
    energy_j = scene.laser.pulse_energy_j
    pe = scene.counter.qe * energy_j * np.sum(echo.weights, axis=1) * scene.laser.wavelength_m
    pe = pe / (H * C)  # photoelectrons per pulse of each lit pixel
    return Response(
        peak_power_w=echo.features.peak_w_per_j * energy_j,
        snr=np.sqrt(pe),  # a Poisson count's S / sqrt(S)
        noise_figures={"signal_pe_median": float(np.median(pe)) if len(pe) else 0.0},
    )


def detect(scene, echo, response: Response) -> Detection:
    pe = response.snr**2
    weights, arrivals = np.asarray(echo.weights), np.asarray(echo.arrivals_s)
    total = np.where(weights.sum(axis=1) > 0, weights.sum(axis=1), 1.0)
    range_true_m = 0.5 * C * (arrivals * weights).sum(axis=1) / total
    sigma_m = 0.5 * C * np.sqrt(2.0) * echo.shape.tau_s / echo.shape.a / np.sqrt(np.maximum(pe, 1))
    p_detect = special.pdtrc(np.ceil(scene.counter.threshold_pe) - 1.0, pe)
    rng = np.random.default_rng([scene.seed, 2024])
    detected = rng.random(len(pe)) < p_detect
    noise = rng.standard_normal(len(pe)) * sigma_m
    return Detection(
        p_detect=p_detect,
        detected=detected,
        range_true_m=range_true_m,
        range_sigma_m=sigma_m,
        range_m=np.where(detected, range_true_m + noise, np.nan),
        threshold_w=float("nan"),  # a threshold in photoelectrons, not in watts
        n_false_per_pixel=0.0,
        outliers=Outliers(pixel=np.zeros(0, np.int64), range_m=np.zeros(0)),
        point_attributes={"photoelectrons": (pe, np.zeros(0))},
        summary_figures={"counter.signal_pe_median": float(np.median(pe)) if len(pe) else 0.0},
    )


RECEIVER = Receiver(
    kind="ideal_counter",
    doc="ideal photon counter: no dead time, dark counts or background (docs/examples)",
    section=Section(name="counter", keys=Counter),
    response_reads=lambda s: (s.laser.pulse_energy_j, s.laser.wavelength_m, s.counter.qe),
    respond=respond,
    detection_reads=lambda s: (s.seed, s.counter.threshold_pe),
    detect=detect,
    summary_figures=(Figure(name="counter.signal_pe_median", unit="1", doc="median count"),),
    point_attributes=(Attribute(name="photoelectrons", unit="1", doc="mean count per pulse"),),
    label="Ideal counter",
    short="counter",
    description="ideal photon counter, QE {scene[counter][qe]:g}",
    glossary=(
        (
            "Count threshold",
            "Ideal counter: the photoelectrons of one pulse a pixel must count to detect its "
            "echo (no noise: the only chance is the count's own Poisson spread).",
        ),
    ),
    controls=(
        Control(
            name="counter_qe",
            key="counter.qe",
            label="Counter QE",
            unit="",
            lo=0.01,
            hi=1.0,
            step=0.01,
            terms=("PDE",),
        ),
        Control(
            name="counter_threshold_pe",
            key="counter.threshold_pe",
            label="Count threshold",
            unit="pe",
            lo=1.0,
            hi=100.0,
            step=1.0,
            terms=("Count threshold",),
        ),
    ),
    stats_rows=(
        StatsRow(label="Echo photoelectrons / pulse", text="{noise[signal_pe_median]:.3g}"),
    ),
    snr_name="count SNR √S",
    snr_stats_label="Median count SNR √S",
    threshold_on_snr_axis=False,
)

if __name__ == "__main__":  # python ideal_counter.py: register it, then run the lmapd command
    import sys

    from simcore.cli import main

    register(RECEIVER)
    sys.exit(main(sys.argv[1:]))
