"""The LM-APD and its amplifier chain: responsivity, gain, noise and SNR (Eqs. 7-18).

All currents in amperes, powers in watts, bandwidths in hertz. Noise figures are rms currents
referred to the APD output (input of the amplifier chain).

The model: docs/physics.md#receiver (Eqs. 7-18: docs/physics.md#eq-7 ... docs/physics.md#eq-18).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...constants import K_B, Q_E, C, H
from ...scene import Amplifiers, Detector, SceneError

PAPER_QUANTUM_EFFICIENCY = 0.6  # the paper's "about 0.6 for Si"
MAX_GAIN = 1e6  # refused above: far beyond any linear-mode APD (Si 20-400, Table 2)


def unity_gain_responsivity_a_w(quantum_efficiency: float, wavelength_m: float) -> float:
    """Eq. 8 with M = 1: eta_q q_e lambda / (h c) [A/W]."""
    return quantum_efficiency * Q_E * wavelength_m / (H * C)


def miller_gain(bias_voltage_v: float, breakdown_voltage_v: float, exponent: float) -> float:
    """Eq. 9, Miller's law M = 1 / (1 - (V/V_B)^n). V >= V_B is refused, not infinite."""
    if not bias_voltage_v < breakdown_voltage_v:
        raise SceneError(
            f"detector.bias_voltage_v = {bias_voltage_v:g} V must be below the breakdown voltage "
            f"{breakdown_voltage_v:g} V (Eq. 9)"
        )
    return 1.0 / (1.0 - (bias_voltage_v / breakdown_voltage_v) ** exponent)


def excess_noise_factor(gain: float, k: float) -> float:
    """Eq. 11, McIntyre: F = k M + (1 - k)(2 - 1/M)."""
    return k * gain + (1.0 - k) * (2.0 - 1.0 / gain)


def friis_noise_factor(noise_factors, power_gains) -> float:
    """Eq. 17, Friis: F1 + (F2-1)/G1 + (F3-1)/(G1 G2) + ... with linear power gains."""
    total, gain = 0.0, 1.0
    for j, (f, g) in enumerate(zip(noise_factors, power_gains, strict=True)):
        total += f if j == 0 else (f - 1.0) / gain
        gain *= g
    return total


@dataclass(frozen=True)
class ReceiverModel:
    """Detector constants that do not depend on the signal."""

    gain: float  # M [1]
    responsivity_a_w: float  # R_resp with gain [A/W] (Eq. 8)
    excess_noise: float  # F [1] (Eq. 11)
    chain_noise_factor: float  # F_chain [1] (Eq. 17)
    bandwidth_hz: float  # B [Hz]
    dark_noise_a: float  # i_nd [A] rms (Eq. 12)
    thermal_noise_a: float  # i_nt [A] rms (Eq. 13)
    snr_max: float

    @property
    def sigma_n_a(self) -> float:
        """Signal-free noise at the discriminator (input-referred) [A rms]:
        sqrt(F_chain (i_nd^2 + i_nt^2))."""
        return float(
            np.sqrt(self.chain_noise_factor * (self.dark_noise_a**2 + self.thermal_noise_a**2))
        )

    def shot_noise_a(self, current_a):
        """Eq. 10: i_ns = sqrt(2 q B i_s M F), the signal shot noise [A rms] of a current i_s."""
        i = np.maximum(np.asarray(current_a, dtype=np.float64), 0.0)
        return np.sqrt(2.0 * Q_E * self.bandwidth_hz * i * self.gain * self.excess_noise)

    def snr_apd(self, current_a):
        """Eq. 14: i_pk / sqrt(i_ns(i_pk)^2 + i_nd^2 + i_nt^2) [1]."""
        i = np.maximum(np.asarray(current_a, dtype=np.float64), 0.0)
        noise2 = self.shot_noise_a(i) ** 2 + self.dark_noise_a**2 + self.thermal_noise_a**2
        return i / np.sqrt(noise2)

    def snr(self, current_a):
        """Eq. 18: SNR after the amplifier chain, SNR_apd / sqrt(F_chain), capped at snr_max."""
        return np.minimum(self.snr_apd(current_a) / np.sqrt(self.chain_noise_factor), self.snr_max)

    def peak_current_for_snr(self, snr):
        """The band-limited peak current [A] whose SNR (Eq. 18) is ``snr``: the positive root of
        i^2 = SNR^2 F_chain (2 q B M F i + i_nd^2 + i_nt^2) (the inverse of :meth:`snr`)."""
        a = self.chain_noise_factor * 2.0 * Q_E * self.bandwidth_hz * self.gain * self.excess_noise
        b = self.chain_noise_factor * (self.dark_noise_a**2 + self.thermal_noise_a**2)
        s2 = np.asarray(snr, dtype=np.float64) ** 2
        return 0.5 * (s2 * a + np.sqrt(s2 * s2 * a * a + 4.0 * s2 * b))

    def sigma_peak_a(self, current_a):
        """Noise at the echo peak (shot + dark + thermal, through the chain) [A rms] (Eq. 27)."""
        i = np.maximum(np.asarray(current_a, dtype=np.float64), 0.0)
        noise2 = self.shot_noise_a(i) ** 2 + self.dark_noise_a**2 + self.thermal_noise_a**2
        return np.sqrt(self.chain_noise_factor * noise2)


def receiver_model(
    detector: Detector, amplifiers: Amplifiers, wavelength_m: float, paper_qe: bool = False
) -> ReceiverModel:
    """Resolve gain and responsivity from the detector section and compute the fixed noise terms."""
    qe = PAPER_QUANTUM_EFFICIENCY if paper_qe else detector.quantum_efficiency
    r0 = unity_gain_responsivity_a_w(qe, wavelength_m)
    if detector.gain_from == "responsivity":
        gain = detector.responsivity_a_w / r0
        if gain < 1.0:
            raise SceneError(
                f"detector.responsivity_a_w = {detector.responsivity_a_w:g} A/W is below the "
                f"unity-gain responsivity {r0:.3g} A/W at this wavelength and quantum efficiency"
            )
    elif detector.gain_from == "gain":
        gain = detector.gain
    else:
        gain = miller_gain(
            detector.bias_voltage_v, detector.breakdown_voltage_v, detector.miller_exponent
        )
    if not gain <= MAX_GAIN:
        raise SceneError(
            f"the APD gain this detector section implies, M = {gain:.3g} (detector.gain_from = "
            f"{detector.gain_from}), is above {MAX_GAIN:g}: no linear-mode APD works there; check "
            "detector.responsivity_a_w, quantum_efficiency or bias_voltage_v"
        )
    f = excess_noise_factor(gain, detector.excess_noise_k)
    b = detector.bandwidth_hz
    dark = np.sqrt(2.0 * Q_E * (detector.dark_surface_a + detector.dark_bulk_a * gain**2 * f) * b)
    thermal = np.sqrt(4.0 * K_B * detector.temperature_k * b / detector.load_ohm)
    return ReceiverModel(
        gain=float(gain),
        responsivity_a_w=float(r0 * gain),
        excess_noise=float(f),
        chain_noise_factor=friis_noise_factor(amplifiers.noise_factors, amplifiers.power_gains),
        bandwidth_hz=b,
        dark_noise_a=float(dark),
        thermal_noise_a=float(thermal),
        snr_max=detector.snr_max,
    )
