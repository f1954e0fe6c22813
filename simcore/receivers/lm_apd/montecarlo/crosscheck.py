"""Cross-checks of the statistical model: the CFD jitter with the signal's own shot noise at the
instants the CFD compares, and the whole gate for synthetic echoes of a scene."""

from __future__ import annotations

import numpy as np

from ....constants import C
from ....pulse import A_FWHM, PulseShape, default_time_step_s, pulse_shape
from ..apd import Q_E, ReceiverModel
from ..timing import cfd_delay_s
from .discriminator import raw_end_s
from .gate import McResult, montecarlo_gate


def cfd_sigma_shot_aware_m(
    shape: PulseShape,
    receiver: ReceiverModel,
    i_pk_a: float,
    t_d_s: float,
    cfd_fraction: float,
) -> float:
    """Linearised CFD range jitter of a single-surface echo with time-dependent shot noise [m].

    Eq. 25 (ours) puts the noise of the peak, sigma_pk (with the peak's shot noise), into both
    terms of ``s = y(t - t_d) - k y(t)``. The CFD fires near the peak of y(t) while the delayed
    copy is at half its peak, where the shot noise is smaller. With the noise covariance
    ``Cov(t1, t2) = sigma_n^2 rho_n(t1 - t2) + F_chain q M F int h_B(t1 - u) h_B(t2 - u) i_s(u) du``
    the jitter is ``(c/2) sqrt(Var(n(t* - t_d) - k n(t*))) / |ds/dt(t*)|``. Without shot noise
    it equals Eq. 25 exactly.

    i_pk_a : band-limited peak signal current [A]; t_d_s, cfd_fraction : Eq. 19 delay [s], fraction.
    """
    scale = i_pk_a / shape.peak_w_per_j  # [A per (W/J)]
    sigma = shape.sigma_h_s

    def mu(t):
        return scale * shape.filtered_at(t)

    # t*: noise-free CFD crossing of the continuous echo, between its half-maximum and peak + t_d
    grid = np.linspace(shape.t_half_s, shape.t_peak_s + t_d_s, 20001)
    s = mu(grid - t_d_s) - cfd_fraction * mu(grid)
    i = np.flatnonzero((s[:-1] < 0) & (s[1:] >= 0))[-1]
    t_star = grid[i] - s[i] * (grid[i + 1] - grid[i]) / (s[i + 1] - s[i])
    h = 1e-3 * sigma
    slope = (
        (mu(t_star - t_d_s + h) - mu(t_star - t_d_s - h)) / (2 * h)
        - cfd_fraction * (mu(t_star + h) - mu(t_star - h)) / (2 * h)
    )[()]
    u = np.linspace(shape.t0_s, raw_end_s(shape), 200001)
    du = u[1] - u[0]
    i_s = scale * shape.raw_at(u)  # the unfiltered signal current [A]

    def h_b(t):
        return np.exp(-0.5 * (t / sigma) ** 2) / (np.sqrt(2 * np.pi) * sigma)

    shot = receiver.chain_noise_factor * Q_E * receiver.gain * receiver.excess_noise

    def cov(t1, t2):
        white = receiver.sigma_n_a**2 * np.exp(-((t1 - t2) ** 2) / (4 * sigma**2))
        return white + shot * np.sum(h_b(t1 - u) * h_b(t2 - u) * i_s) * du

    t1, t2 = t_star - t_d_s, t_star
    var = cov(t1, t1) + cfd_fraction**2 * cov(t2, t2) - 2 * cfd_fraction * cov(t1, t2)
    return float(0.5 * C * np.sqrt(var) / abs(slope))


def scene_gate(
    rng: np.random.Generator,
    scene,
    receiver: ReceiverModel,
    arrivals_s,
    weights_per_j,
    *,
    tnr: float,
    gate_m: float,
    n_pixels_total: int | None = None,
    **options,
) -> McResult:
    """:func:`montecarlo_gate` for synthetic echoes, its pulse, band limit, CFD, timing and gate
    centre (the target distance) taken from ``scene``; pixels are numbered 0..n-1. ``options``
    pass on (holdoff_s, noise, arming, first_stop, max_bytes, n_threads, or resolution_s to
    override the scene's)."""
    tau, b_hz = scene.laser.pulse_width_s, scene.detector.bandwidth_hz
    shape = pulse_shape(tau, A_FWHM, b_hz)
    n = len(arrivals_s)
    return montecarlo_gate(
        rng,
        pixel=np.arange(n),
        arrivals_s=arrivals_s,
        weights_per_j=weights_per_j,
        shape=shape,
        dt_s=default_time_step_s(tau, b_hz),
        receiver=receiver,
        pulse_energy_j=scene.laser.pulse_energy_j,
        n_pixels_total=n if n_pixels_total is None else n_pixels_total,
        gate_center_m=scene.pose.distance_m,
        gate_m=gate_m,
        tnr=tnr,
        t_d_s=cfd_delay_s(shape),
        cfd_fraction=scene.timing.cfd_fraction,
        resolution_s=options.pop("resolution_s", scene.timing.resolution_s),
        **options,
    )
