"""The laser pulse and its band-limited copy (Eqs. 1, 4): the reference every echo is built from.

The band-limited pulse p_B = h_B * P0 (Gaussian impulse response of the detector + amplifiers
convolved with the Q-switched pulse of Eq. 1) has a closed form, an exponentially modified Gaussian.
It is tabulated once per pulse at a few picoseconds and interpolated, so every echo
y(t) = sum_k w_k p_B(t - t_k) is evaluated at exact delays, never snapped to the time grid.

The model: docs/physics.md#pulse, docs/physics.md#band-limit, docs/physics.md#emg.
"""

from __future__ import annotations

import hashlib
import json
import math
import warnings
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import scipy
from scipy import special

from .cache import cache_dir, write_atomically

if TYPE_CHECKING:
    from .scene import Scene

A_FWHM = 2.446386  # Eq. 1 constant for which tau is the FWHM (ours)
A_PAPER = 3.5  # Eq. 1 constant printed in the paper (FWHM = 0.699 tau)
_TABLE_SIZE = 1 << 15
MARKS_MAX_ENTRIES = 256  # pulses whose timing marks the on-disk cache keeps


def pulse_power_w(t_s, energy_j: float, tau_s: float, a: float = A_FWHM):
    """Eq. 1: P0(t) = Pmax (a t / tau) exp(1 - a t / tau) for t >= 0, with Pmax = a E / (e tau)."""
    t = np.asarray(t_s, dtype=np.float64)
    x = np.maximum(a * t / tau_s, 0.0)
    p_max = a * energy_j / (math.e * tau_s)
    return np.where(t >= 0, p_max * x * np.exp(1.0 - x), 0.0)


def band_limit_sigma_s(bandwidth_hz: float) -> float:
    """sigma_h of the Gaussian impulse response whose noise-equivalent bandwidth is B:
    B = integral |H|^2 df = 1 / (4 sqrt(pi) sigma_h)."""
    return 1.0 / (4.0 * np.sqrt(np.pi) * bandwidth_hz)


def filtered_pulse_w(t_s, energy_j: float, tau_s: float, a: float, sigma_s: float):
    """(h_B * P0)(t) in closed form [W]: P0 of Eq. 1 through a unit-area Gaussian of std sigma.

    With lam = a / tau and mu = t - lam sigma^2,
    h_B * P0 = Pmax e lam exp(-lam t + lam^2 sigma^2 / 2) [mu Phi(mu/sigma) + sigma phi(mu/sigma)],
    evaluated as exp(-t^2 / (2 sigma^2)) [mu erfcx(-mu/(sigma sqrt 2)) / 2 + sigma / sqrt(2 pi)]
    where mu <= 0, so that it never overflows.
    """
    t = np.asarray(t_s, dtype=np.float64)
    lam = a / tau_s
    p_max = a * energy_j / (math.e * tau_s)
    mu = t - lam * sigma_s**2
    out = np.empty_like(t)
    neg = mu <= 0
    tn, mn = t[neg], mu[neg]
    out[neg] = np.exp(-(tn**2) / (2 * sigma_s**2)) * (
        0.5 * mn * special.erfcx(-mn / (sigma_s * np.sqrt(2))) + sigma_s / np.sqrt(2 * np.pi)
    )
    tp, mp = t[~neg], mu[~neg]
    z = mp / sigma_s
    out[~neg] = np.exp(-lam * tp + 0.5 * (lam * sigma_s) ** 2) * (
        mp * special.ndtr(z) + sigma_s * np.exp(-0.5 * z * z) / np.sqrt(2 * np.pi)
    )
    return p_max * math.e * lam * out


@dataclass(frozen=True, kw_only=True)
class PulseShape:
    """The emitted pulse and its band-limited copy, tabulated per joule.

    Times are relative to the pulse start (t = 0 of Eq. 1). ``t_half_s`` and ``t_peak_s`` are the
    half-maximum (rising edge) and peak times of the band-limited reference pulse y0.
    """

    tau_s: float
    a: float
    sigma_h_s: float
    t0_s: float  # first table time
    step_s: float  # table step
    filtered: np.ndarray  # (N,) W/J
    raw: np.ndarray  # (N,) W/J
    t_half_s: float
    t_peak_s: float
    peak_w_per_j: float
    t_start_s: float  # before this the band-limited pulse is < 1e-5 of its peak
    t_end_s: float  # after this it is < 1e-4 of its peak
    filtered_slope: np.ndarray  # (N,) next-sample differences of the tables, for the lookup
    raw_slope: np.ndarray
    # (N,) W/J: P0 through h_B^2 normalised to unit area (a Gaussian of sigma_h / sqrt 2): the
    # current whose shot noise a band-limited sample carries (docs/physics.md#eq-25)
    shot: np.ndarray
    shot_slope: np.ndarray

    def lookup(self, table: np.ndarray, t_s):
        """Linear interpolation of ``filtered`` or ``raw`` at times t. Both tables are ~0 at their
        ends (< 1e-10 of the peak), so times outside them clamp to an end value."""
        slopes = self._slopes[id(table)]
        shape = np.shape(t_s)
        x = np.array(t_s, dtype=np.float64, ndmin=1)  # a copy, worked on in place
        x -= self.t0_s
        x *= 1.0 / self.step_s
        np.clip(x, 0.0, len(table) - 2, out=x)
        i = x.astype(np.int32)
        x -= i  # the fraction
        x *= slopes[i]
        x += table[i]
        return x.reshape(shape)

    def slope_of(self, table: np.ndarray) -> np.ndarray:
        """The next-sample differences of ``filtered``, ``raw`` or ``shot``."""
        return self._slopes[id(table)]

    @property
    def _slopes(self) -> dict[int, np.ndarray]:
        return {
            id(self.filtered): self.filtered_slope,
            id(self.raw): self.raw_slope,
            id(self.shot): self.shot_slope,
        }

    def rising_time_s(self, fraction: float) -> float:
        """Time on the rising edge where the band-limited pulse is ``fraction`` of its peak."""
        t = self.t0_s + self.step_s * np.arange(len(self.filtered))
        rising = t <= self.t_peak_s
        level = fraction * self.peak_w_per_j
        return float(np.interp(level, self.filtered[rising], t[rising]))

    @cached_property
    def rise_time_10_90_s(self) -> float:
        """10-90 % rise time of the band-limited pulse (see timing.rise_time_10_90_s)."""
        return self.rising_time_s(0.9) - self.rising_time_s(0.1)

    def filtered_at(self, t_s):
        return self.lookup(self.filtered, t_s)

    def raw_at(self, t_s):
        return self.lookup(self.raw, t_s)

    def shot_at(self, t_s):
        return self.lookup(self.shot, t_s)


@lru_cache(maxsize=16)
def pulse_shape(tau_s: float, a: float, bandwidth_hz: float) -> PulseShape:
    """Tabulate P0 and h_B * P0 (per joule) and find the reference pulse's timing marks."""
    sigma = band_limit_sigma_s(bandwidth_hz)
    t = table_times_s(tau_s, a, sigma)
    filt = filtered_pulse_w(t, 1.0, tau_s, a, sigma)
    raw = pulse_power_w(t, 1.0, tau_s, a)
    shot = filtered_pulse_w(t, 1.0, tau_s, a, sigma / np.sqrt(2.0))
    t_pk, peak, t_half = cached_timing_marks(
        (tau_s, a, bandwidth_hz), lambda: timing_marks(t, filt, tau_s, a, sigma)
    )
    start = t[np.argmax(filt > 1e-5 * peak)]
    end = t[len(t) - 1 - np.argmax(filt[::-1] > 1e-4 * peak)]
    slopes = [np.diff(arr, append=arr[-1]) for arr in (filt, raw, shot)]
    for arr in (filt, raw, shot, *slopes):
        arr.setflags(write=False)
    filtered_slope, raw_slope, shot_slope = slopes
    return PulseShape(
        tau_s=tau_s,
        a=a,
        sigma_h_s=sigma,
        t0_s=float(t[0]),
        step_s=float(t[1] - t[0]),
        filtered=filt,
        raw=raw,
        t_half_s=t_half,
        t_peak_s=t_pk,
        peak_w_per_j=peak,
        t_start_s=start,
        t_end_s=end,
        filtered_slope=filtered_slope,
        raw_slope=raw_slope,
        shot=shot,
        shot_slope=shot_slope,
    )


def table_times_s(tau_s: float, a: float, sigma_s: float) -> np.ndarray:
    """(N,) times of the pulse tables [s]: from 9 sigma_h before the pulse starts to where Eq. 1
    has fallen below 1e-11 of its peak (x e^(1-x) at x = 30), plus 9 sigma_h."""
    t0 = -9.0 * sigma_s
    t1 = 30.0 / (a / tau_s) + 9.0 * sigma_s
    return np.linspace(t0, t1, _TABLE_SIZE)


def timing_marks(t_s, filtered, tau_s: float, a: float, sigma_s: float) -> tuple[float, ...]:
    """Peak time [s], peak [W/J] and rising half-maximum time [s] of the band-limited pulse, from
    its table (``t_s``, ``filtered``: (N,)) refined on the closed form with scipy.optimize."""
    from scipy import optimize  # noqa: PLC0415  (0.3 s to import: only for a pulse not cached)

    i_pk = int(np.argmax(filtered))
    f = lambda x: -filtered_pulse_w(np.array([x]), 1.0, tau_s, a, sigma_s)[0]  # noqa: E731
    bracket = (t_s[i_pk - 1], t_s[i_pk], t_s[i_pk + 1])
    res = optimize.minimize_scalar(f, bracket=bracket, tol=1e-12)
    t_pk, peak = float(res.x), float(-res.fun)
    half = lambda x: filtered_pulse_w(np.array([x]), 1.0, tau_s, a, sigma_s)[0] - 0.5 * peak  # noqa: E731
    t_half = optimize.brentq(half, t_s[0], t_pk, xtol=1e-16, rtol=1e-14)
    return t_pk, peak, float(t_half)


_MARKS = ("t_peak_s", "peak_w_per_j", "t_half_s")


def _marks_file(folder: Path, pulse: tuple[float, ...]) -> Path:
    """The cache entry of a pulse's marks: named by the pulse (tau, a, bandwidth, exactly), this
    module's source and the numpy and scipy that computed them."""
    digest = hashlib.sha256(Path(__file__).read_bytes())
    versions = f"numpy {np.__version__} scipy {scipy.__version__}"
    digest.update(f"{' '.join(float(v).hex() for v in pulse)} {versions}".encode())
    return folder / "pulses" / f"{digest.hexdigest()}.json"


def _read_marks(file: Path) -> tuple[float, ...] | None:
    """The marks stored in ``file`` (exact: hexadecimal floats); None if there are none, with a
    warning if the entry is corrupt."""
    try:
        stored = json.loads(file.read_text(encoding="ascii"))
        marks = tuple(float.fromhex(stored[name]) for name in _MARKS)
        t_pk, peak, t_half = marks
        if not (all(map(math.isfinite, marks)) and peak > 0 and t_half < t_pk):
            raise ValueError("inconsistent marks")
        return marks
    except (FileNotFoundError, NotADirectoryError):
        return None
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        warnings.warn(f"pulse cache {file} is corrupt ({exc}); rebuilt", stacklevel=4)
        return None


def cached_timing_marks(pulse: tuple[float, ...], compute) -> tuple[float, ...]:
    """``compute()`` (the timing marks of ``pulse``), kept in the on-disk cache: finding them
    needs scipy.optimize, whose import costs several times the search (a corrupt entry is
    rebuilt, an unwritable cache skipped, each with a warning)."""
    folder = cache_dir()
    try:
        file = _marks_file(folder, pulse) if folder is not None else None
    except OSError:  # this module's source is not readable: no cache
        file = None
    marks = _read_marks(file) if file is not None else None
    if marks is not None:
        return marks
    marks = compute()
    if file is not None:
        text = json.dumps({name: float(v).hex() for name, v in zip(_MARKS, marks, strict=True)})
        try:
            write_atomically(file, lambda fh: fh.write(text.encode("ascii")), MARKS_MAX_ENTRIES)
        except OSError as exc:
            warnings.warn(f"pulse cache {file.parent} is not writable ({exc})", stacklevel=3)
    return marks


def default_time_step_s(tau_s: float, bandwidth_hz: float) -> float:
    """Section 5: dt <= min(tau / 10, 1 / (20 B))."""
    return min(tau_s / 10.0, 1.0 / (20.0 * bandwidth_hz))


def pulse_constant(scene: Scene) -> float:
    """Eq. 1's a: ours (tau the FWHM) or the paper's printed 3.5."""
    return A_PAPER if scene.uses("pulse_constant") else A_FWHM


def scene_pulse_shape(scene: Scene) -> PulseShape:
    """The scene's emitted pulse through its band limit (tabulated once per pulse)."""
    return pulse_shape(
        scene.laser.pulse_width_s, pulse_constant(scene), scene.detector.bandwidth_hz
    )


def cfd_delay_s(shape: PulseShape, delay_s: float = 0.0) -> float:
    """Eq. 19 default delay t_d = t_peak - t_half of the band-limited reference pulse (2.24 ns for
    the paper's 5 ns pulse at 120 MHz): with a CFD fraction of 0.5 the CFD then fires when the
    delayed copy is at half its peak, the instant of Eq. 31. A positive ``delay_s`` overrides it."""
    return delay_s if delay_s > 0 else shape.t_peak_s - shape.t_half_s
