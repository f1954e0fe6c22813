"""The waveform Monte Carlo model (docs/physics.md#monte-carlo): noisy currents through the band
limit and the constant-fraction discriminator itself, over the whole range gate of every pixel.

It checks the statistical model (Eqs. 24-28) by simulating what it summarises:

1. Signal current ``i_s(t) = R_resp P_r(t)`` (Eqs. 7, 29-30) sampled at ``dt``; white current
   samples ``N(0, S(t) / (2 dt))`` with the one-sided density
   ``S(t) = F_chain [2 q_e (i_s(t) M F + I_ds + I_db M^2 F) + 4 k_B T / R_L]`` are added to it
   BEFORE the band limit; the sum is convolved with the Gaussian ``h_B`` (unit area).
2. A discriminator over the whole gate: it arms where ``y`` crosses ``V_T = TNR sigma_n`` upwards
   and fires by the Eq. 19 rule (last upward zero crossing of ``s(t) = y(t - t_d) - k y(t)``, k the
   CFD fraction, in ``[t_a - t_d, t_pk + t_d]``). Multi-stop by default, with a re-arm hold-off
   of one pulse FWHM.
3. A stop inside ``[min 2 r_k / c - tau, max 2 r_k / c + 2 tau]`` is a detection, any other stop a
   false alarm. Time of flight ``(t*_stop + e1) - (t*_ref + e2)`` with ``e1, e2 ~ U(-T_t/2, T_t/2)``
   (Eq. 26); ``t*_ref`` is the emitted pulse through the same band limit and discriminator.

Arming is continuous-time. The model's current is a continuous function,
``y(t) = sum_i x_i h_B(t - t_i) dt`` (``x_i`` the white + signal samples), so the comparator sees
every excursion above ``V_T``, also one that starts and ends between two samples: such pairs of
samples (both below ``V_T`` but within 15 % of it) are re-evaluated exactly at ``dt / 8`` from the
same ``x_i``. A comparator that looks at the samples only misses them and counts 3 % (TNR 3) to
9 % (TNR 6) fewer false alarms than the Rice rate at the default step (``arming="sampled"``
reproduces that; the exact count of sampled up-crossings is in the tests).

Where it differs from the statistical model (measured in tests/core/test_montecarlo.py and
scripts/plot_mc_agreement.py):

- P_d: Eq. 27 is a single look at the peak. The discriminator also arms on noise inside the
  detection window and on any sample of the pulse top: up to +0.24 at SNR = TNR = 2, +0.16 at
  TNR 3, +0.10 at TNR 4, below 0.1 from TNR 5 up. A noise stop shortly before an echo blocks it
  for the hold-off (P_d 0.97 at SNR 50, TNR 2).
- Range noise: Eq. 25 (ours) puts the shot noise of the peak into both CFD terms; the delayed
  copy is sampled at half the peak, where it is lower, so with shot noise the MC jitter is up to
  18 % below Eq. 25 (SNR 20); :func:`cfd_sigma_shot_aware_m` follows the MC.
- Waveform bias: for a multi-surface pixel the CFD fires on the first surface that crosses V_T;
  Eq. 31 times the half maximum of the strongest. Single surfaces agree to a few millimetres
  (sampling: the pulse-onset kink, the linear delayed copy and the linear crossing).
- False alarms: the Rice rate for up-crossings; the hold-off drops re-triggers within one FWHM
  (-4 % at TNR 2, nothing measurable from TNR 3).
- Gross errors: near the threshold the discriminator arms on a noise-lifted onset (the CFD then
  fires up to 0.6 m early) or on the trailing edge (0.3-0.45 m late): about 1 % of the stops at
  SNR 6, TNR 5. The statistical model draws them from a table this model makes
  (``simcore.receivers.lm_apd.gross_errors``, docs/physics.md#gross-errors).

Every pixel of the array is simulated over the whole gate, lit or not, in chunks of pixels whose
working set is at most ``max_bytes`` per worker thread, so memory stays bounded whatever the pixel
count. Each pixel draws its Gaussian white noise from its own stream (a 64-bit key drawn once per
flash from the caller's generator, and the pixel's index: ``noise``), on every second sample at
the default step (docs/physics.md#mc-noise-draw); the timing quantisation comes from child
generators spawned one per chunk. A run is reproducible for a given seed and ``max_bytes`` (the
chunking), whatever the number of threads.

The package, one module per step:

``currents``       noisy currents through the band limit (step 1)
``discriminator``  arming, the CFD stop, the hold-off, the reference stop (step 2)
``noise``          the compiled noise kernel: per-pixel streams, the white step, the filter
``gate``           the whole gate of the whole array, in chunks on threads; the pipeline's entry
                   point :func:`montecarlo_detection` (step 3)
``crosscheck``     the shot-noise-aware CFD jitter; the gate for synthetic echoes of a scene
"""

from .crosscheck import cfd_sigma_shot_aware_m, scene_gate
from .currents import (
    KERNEL_HALF_WIDTH_SIGMA,
    BandLimit,
    band_limit,
    noise_density_a2_hz,
    simulate_current_waveforms,
)
from .discriminator import (
    ARMING_CURVATURE,
    ARMING_MARGIN,
    ARMING_REFINE,
    ARMING_SLACK,
    RAW_TAIL,
    Stops,
    discriminate,
    pulse_fwhm_s,
    reference_stop_s,
)
from .gate import McResult, gate_samples, montecarlo_detection, montecarlo_gate

__all__ = [
    "ARMING_CURVATURE",
    "ARMING_MARGIN",
    "ARMING_REFINE",
    "ARMING_SLACK",
    "KERNEL_HALF_WIDTH_SIGMA",
    "RAW_TAIL",
    "BandLimit",
    "McResult",
    "Stops",
    "band_limit",
    "cfd_sigma_shot_aware_m",
    "discriminate",
    "gate_samples",
    "montecarlo_detection",
    "montecarlo_gate",
    "noise_density_a2_hz",
    "pulse_fwhm_s",
    "reference_stop_s",
    "scene_gate",
    "simulate_current_waveforms",
]
