"""Gross range errors of the discriminator at low SNR, taken from the Monte Carlo's own
discriminator for the statistical model (docs/physics.md#gross-errors).

Near the threshold the constant-fraction discriminator (Eq. 19) does not only jitter: about 1 %
of its stops at SNR 6 and TNR 5 lie 0.25-0.6 m early, a few 0.3-0.45 m late. Early: noise lifts
the echo's onset, the comparator arms there, and the CFD signal s(t) = y(t - t_d) - k y(t) sees
the lifted onset in its delayed copy, so it turns positive at the onset and stays positive
through the echo's own zero crossing; the last upward crossing in the window, the stop, is the
onset's, up to the pulse's rise (2.6 ns, 0.39 m) and the CFD delay before the true one. Late: the
echo's peak stays below V_T, noise on its trailing edge arms the comparator, the window holds no
zero crossing and the stop is the arming time. Eq. 25 linearises the CFD about its zero crossing
and cannot see either.

The statistical model takes their probability and their displacement from a short run of the
waveform Monte Carlo itself: single-surface echoes at a grid of SNRs (``WAVEFORMS_PER_SNR`` each,
at random sample phases, a fixed seed) through the scene's receiver, band limit, threshold, CFD
and timing, first stop. A stop more than ``GROSS_SIGMAS`` statistical sigmas (Eq. 24, ours) from
the true range is a gross error; per SNR the share of the detected echoes that are gross, and
all gross displacements pooled, form the table. The grid runs from ``TNR - GRID_BELOW_TNR`` to
``TNR + GRID_ABOVE_TNR``: above it the share is below 1.5e-4 (none of 20,000 at SNR 12, TNR 5).

The table is computed once per receiver, pulse and threshold (about 1 s) and kept in memory and
in the user's on-disk cache (``simcore.cache``), so the Monte Carlo is imported only to make it;
thresholds between multiples of ``TNR_STEP`` interpolate the two tables around them
(:func:`gross_errors_at`), so that a TNR slider does not pay a table for every value it passes.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import math
import warnings
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from ...cache import cache_dir, write_atomically
from ...constants import C
from ...pulse import pulse_shape
from .apd import ReceiverModel

GROSS_SIGMAS = 4.0  # a stop this many Eq. 24 sigmas from the true range is a gross error
GRID_BELOW_TNR = 2.0  # the SNR grid starts this far below the TNR (at 1 at least)...
GRID_ABOVE_TNR = 7.0  # ...and ends this far above it
GRID_STEP = 1.0  # SNR step of the grid
WAVEFORMS_PER_SNR = 5000  # single-surface echoes simulated per SNR of the grid
GATE_M = 2.5  # the calibration's range gate [m]...
ECHO_AFTER_GATE_M = 0.45  # ...the echoes start this far into it (3 ns: the CFD's look back)
SEED = 25  # the calibration's own seed: a table is the same for every frame
MAX_ENTRIES = 64  # tables kept in the on-disk cache
# refused above: a table's waveform samples x (the band limit's taps + SAMPLE_WORK_TAPS), its work
# in filter taps. Measured on two busy cores: detector.bandwidth_hz = 1e6 9.2e11 (17 s),
# laser.pulse_width_s = 1e-6 at 1e3 Hz 1.5e13 (465 s), 1e11 Hz 3.4e12 (past 90 s)
MAX_CALIBRATION_WORK = 2**41
SAMPLE_WORK_TAPS = 2000  # a sample's own work (its noise draw, the discriminator's passes)
TNR_STEP = 0.5  # tables are computed at TNR multiples of this and interpolated between them


@dataclass(frozen=True)
class GrossErrors:
    """The discriminator's gross errors by SNR, for one receiver, pulse and threshold.

    snr : (m,) the grid of SNR_na (Eq. 18) [1]
    probability : (m,) share of the detected echoes at each SNR that are gross errors [1]
    displacement_m : (q,) every gross error of the run, measured less true range, sorted [m]
    """

    snr: np.ndarray
    probability: np.ndarray
    displacement_m: np.ndarray

    @property
    def snr_max(self) -> float:
        """Above this SNR no gross error is drawn [1]."""
        return float(self.snr[-1]) if len(self.snr) else 0.0

    def probability_at(self, snr) -> np.ndarray:
        """(n,) the gross share at each SNR: linear between grid points, the first point's
        below the grid, 0 above it [1]."""
        s = np.asarray(snr, dtype=np.float64)
        if not len(self.snr) or not len(self.displacement_m):
            return np.zeros(s.shape)
        p = np.interp(s, self.snr, self.probability, right=0.0)
        return np.where(np.isfinite(s) & (s <= self.snr_max), p, 0.0)


def snr_grid(tnr: float) -> np.ndarray:
    """The calibration's SNRs for a threshold at ``tnr`` [1]."""
    lo = max(1.0, tnr - GRID_BELOW_TNR)
    return np.arange(lo, tnr + GRID_ABOVE_TNR + 1e-9, GRID_STEP)


def calibration_work(tau_s: float, bandwidth_hz: float, dt_s: float, tnr: float) -> tuple:
    """(samples, taps): the waveform samples the table of a threshold at ``tnr`` draws, its
    echoes (the grid's SNRs x WAVEFORMS_PER_SNR) x (the gate's samples + the band limit's
    2 m + 1 taps), and those taps (each output sample of the filter sums that many) [1]."""
    del tau_s  # the gate is fixed: the pulse enters through the step
    sigma_h = 1.0 / (4.0 * math.sqrt(math.pi) * bandwidth_hz)
    taps = 2 * math.ceil(6.0 * sigma_h / dt_s) + 1  # KERNEL_HALF_WIDTH_SIGMA either side
    per_echo = 2.0 * GATE_M / C / dt_s + taps
    return float(len(snr_grid(tnr)) * WAVEFORMS_PER_SNR * per_echo), taps


def check_calibration_cost(tau_s: float, bandwidth_hz: float, dt_s: float, tnr: float) -> None:
    """Refuse (SceneError, one line naming the keys) a table whose waveform samples x (taps +
    SAMPLE_WORK_TAPS) pass MAX_CALIBRATION_WORK (minutes of work), before any is drawn: a band
    limit much wider than the step (a 10 ps pulse at 120 MHz: 14,107 taps) or a step much finer
    than the default (1e11 Hz: 0.5 ps over a 17 ns gate)."""
    from ...scene import SceneError  # noqa: PLC0415

    samples, taps = max(
        calibration_work(tau_s, bandwidth_hz, dt_s, tnr + d) for d in (0.0, TNR_STEP)
    )
    work = samples * (taps + SAMPLE_WORK_TAPS)
    if work > MAX_CALIBRATION_WORK:
        raise SceneError(
            f"detector.bandwidth_hz = {bandwidth_hz:g} Hz with laser.pulse_width_s = {tau_s:g} s "
            f"at a time step of {dt_s:.3g} s: the statistical model's gross-error table would "
            f"filter {samples:.2g} waveform samples through {taps} taps (work {work:.2g}, at "
            f"most {MAX_CALIBRATION_WORK:.2g}: minutes): give a "
            "detector.bandwidth_hz nearer 1 / (2 laser.pulse_width_s) or a coarser "
            "fidelity.time_step_s"
        )


def single_surface_sigma_m(
    receiver: ReceiverModel, shape, i_pk_a, dt_s, t_d_s, cfd_fraction, resolution_s
) -> np.ndarray:
    """(m,) Eq. 24 (ours: Eq. 25 per sample, Eq. 26) of single-surface echoes of peak currents
    ``i_pk_a`` [m], as the statistical model computes it."""
    from ...echo import echo_features  # noqa: PLC0415
    from . import timing  # noqa: PLC0415

    feats = echo_features(shape, np.zeros((1, 1)), np.ones((1, 1)), dt_s, t_d_s, cfd_fraction)
    level, slope = feats.cfd_shot_level[0], feats.cfd_slope_per_s[0]
    i = np.asarray(i_pk_a, dtype=np.float64)
    delayed, prompt, mid = (receiver.sigma_peak_a(i * lv) for lv in level)
    args = (cfd_fraction, t_d_s, shape.sigma_h_s)
    s_cfd = timing.sigma_cfd_per_sample_m(i, delayed, prompt, slope, *args, sigma_mid_a=mid)
    if np.isfinite(receiver.snr_max):
        s_cfd = np.maximum(s_cfd, timing.sigma_cfd_m(receiver.snr_max, slope, *args))
    return timing.range_sigma_m(s_cfd, timing.sigma_quantisation_m(resolution_s))


@lru_cache(maxsize=16)
def gross_errors(
    receiver: ReceiverModel,
    tau_s: float,
    a: float,
    bandwidth_hz: float,
    dt_s: float,
    t_d_s: float,
    cfd_fraction: float,
    tnr: float,
    resolution_s: float,
    holdoff_s: float,
) -> GrossErrors:
    """The gross-error table of one receiver, pulse (Eq. 1's tau and a, the band limit), time
    step, CFD (delay, fraction), threshold, timing resolution and re-arm hold-off (module
    docstring); cached in memory and on disk (a corrupt entry is rebuilt, an unwritable cache
    skipped, each with a warning)."""
    args = (
        receiver, tau_s, a, bandwidth_hz, dt_s, t_d_s, cfd_fraction, tnr, resolution_s, holdoff_s,
    )  # fmt: skip
    folder = cache_dir()
    try:
        file = _entry(folder, args) if folder is not None else None
    except OSError:  # the sources are not readable: no disk cache
        file = None
    table = _read(file) if file is not None else None
    if table is not None:
        return table
    table = calibrate(*args)
    if file is not None:
        buffer = io.BytesIO()
        np.savez(buffer, **dataclasses.asdict(table))
        try:
            write_atomically(file, lambda fh: fh.write(buffer.getvalue()), MAX_ENTRIES)
        except OSError as exc:
            warnings.warn(f"gross-error cache {file.parent} is not writable ({exc})", stacklevel=2)
    return table


def gross_errors_at(
    receiver: ReceiverModel,
    tau_s: float,
    a: float,
    bandwidth_hz: float,
    dt_s: float,
    t_d_s: float,
    cfd_fraction: float,
    tnr: float,
    resolution_s: float,
    holdoff_s: float,
) -> GrossErrors:
    """The gross-error table at any threshold: the tables at the two multiples of TNR_STEP
    around ``tnr`` (:func:`gross_errors`, each computed once), their probabilities interpolated
    linearly in the TNR and the nearer one's displacements. A TNR slider dragged across a unit
    then computes at most three tables, not one per value it passes; at a multiple of TNR_STEP
    (TNR 5, the paper's) and below 1 the table is that TNR's own."""
    rest = (resolution_s, holdoff_s)
    head = (receiver, tau_s, a, bandwidth_hz, dt_s, t_d_s, cfd_fraction)
    lo = math.floor(tnr / TNR_STEP) * TNR_STEP
    w = (tnr - lo) / TNR_STEP
    if tnr < 1.0 or w < 1e-9:
        return gross_errors(*head, tnr, *rest)
    below, above = gross_errors(*head, lo, *rest), gross_errors(*head, lo + TNR_STEP, *rest)
    snr = np.union1d(below.snr, above.snr)
    probability = (1.0 - w) * below.probability_at(snr) + w * above.probability_at(snr)
    nearer = below if w < 0.5 else above
    return GrossErrors(snr=snr, probability=probability, displacement_m=nearer.displacement_m)


def _entry(folder: Path, args: tuple) -> Path:
    """The cache entry of a table: named by its arguments (floats exactly), the sources that
    compute it (this module, the pulse and the Monte Carlo) and numpy's and scipy's versions."""
    import scipy  # noqa: PLC0415

    here = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for source in (
        here / "gross_errors.py",
        here.parent.parent / "pulse.py",
        *sorted((here / "montecarlo").glob("*.py")),
    ):
        digest.update(source.read_bytes())
    receiver, *numbers = args
    fields = [getattr(receiver, f.name) for f in dataclasses.fields(receiver)]
    text = " ".join(float(v).hex() for v in (*fields, *numbers))
    digest.update(f"{text} numpy {np.__version__} scipy {scipy.__version__}".encode())
    return folder / "gross_errors" / f"{digest.hexdigest()}.npz"


def _read(file: Path) -> GrossErrors | None:
    """The table stored in ``file``; None if there is none, with a warning if it is corrupt."""
    try:
        with np.load(file) as data:
            table = GrossErrors(**{f.name: data[f.name] for f in dataclasses.fields(GrossErrors)})
        if not (table.snr.shape == table.probability.shape and table.displacement_m.ndim == 1):
            raise ValueError("inconsistent table")
        return table
    except (FileNotFoundError, NotADirectoryError):
        return None
    except (OSError, ValueError, KeyError, TypeError, EOFError) as exc:
        warnings.warn(f"gross-error cache {file} is corrupt ({exc}); rebuilt", stacklevel=3)
        return None


def calibrate(
    receiver: ReceiverModel,
    tau_s: float,
    a: float,
    bandwidth_hz: float,
    dt_s: float,
    t_d_s: float,
    cfd_fraction: float,
    tnr: float,
    resolution_s: float,
    holdoff_s: float,
) -> GrossErrors:
    """Compute the gross-error table (module docstring) by the waveform Monte Carlo."""
    from .montecarlo.gate import montecarlo_gate  # noqa: PLC0415

    shape = pulse_shape(tau_s, a, bandwidth_hz)
    snrs = snr_grid(tnr)
    n_each = WAVEFORMS_PER_SNR
    i_pk = np.repeat(receiver.peak_current_for_snr(snrs), n_each)
    weights = (i_pk / (receiver.responsivity_a_w * shape.peak_w_per_j))[:, None]  # per 1 J
    rng = np.random.default_rng(SEED)
    centre_m = 1000.0
    start_m = centre_m - 0.5 * GATE_M + ECHO_AFTER_GATE_M
    true_m = start_m + rng.uniform(0.0, 0.5 * C * dt_s, size=len(i_pk))  # every sample phase
    res = montecarlo_gate(
        rng,
        pixel=np.arange(len(i_pk)),
        arrivals_s=(2.0 * true_m / C)[:, None],
        weights_per_j=weights,
        shape=shape,
        dt_s=dt_s,
        receiver=receiver,
        pulse_energy_j=1.0,
        n_pixels_total=len(i_pk),
        gate_center_m=centre_m,
        gate_m=GATE_M,
        tnr=tnr,
        t_d_s=t_d_s,
        cfd_fraction=cfd_fraction,
        resolution_s=resolution_s,
        max_stops=1,
        holdoff_s=holdoff_s,
    )
    err = (res.range_m - true_m).reshape(len(snrs), n_each)
    sigma = single_surface_sigma_m(
        receiver, shape, receiver.peak_current_for_snr(snrs), dt_s, t_d_s, cfd_fraction,
        resolution_s,
    )  # fmt: skip
    detected = np.isfinite(err)
    gross = detected & (np.abs(np.where(detected, err, 0.0)) > GROSS_SIGMAS * sigma[:, None])
    n_det = detected.sum(axis=1)
    probability = np.where(n_det > 0, gross.sum(axis=1) / np.maximum(n_det, 1), 0.0)
    return GrossErrors(
        snr=snrs, probability=probability, displacement_m=np.sort(err[gross].astype(np.float64))
    )
