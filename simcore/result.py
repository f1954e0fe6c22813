"""What one flash gives: :class:`Result` (the point cloud, the per-pixel products of every stage,
the stage timings), one pixel's echo as a :class:`Waveform`
(its peaks: ``n_peaks``), and the JSON summary."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import geometry
from . import quality as quality_stage
from .background import Background
from .echo import EchoStage
from .pointcloud import PointCloud
from .receivers import Detection, Response
from .scene import Scene
from .target import TargetModel, parts_table


@dataclass(frozen=True, kw_only=True)
class Waveform:
    """One pixel's echo. Times since emission [s], powers at the receiver input [W]; empty arrays
    and NaN times where the pixel receives no echo."""

    row: int
    col: int
    t_s: np.ndarray  # (L,) sample times
    power_w: np.ndarray  # (L,) unfiltered P_r(t)
    filtered_w: np.ndarray  # (L,) band-limited y(t)
    emitted_t_s: np.ndarray  # (M,) the emitted pulse, band-limited, scaled to this echo's peak
    emitted_w: np.ndarray  # (M,)
    t_half_s: float  # half-maximum time of y (NaN if no echo)
    threshold_w: float  # the receiver's arming threshold expressed as input power
    range_m: float  # measured range, NaN if not detected
    range_true_m: float
    p_detect: float
    detected: bool
    background_w: float = 0.0  # the pixel's background power at the detector (DC, AC-coupled out)


def n_peaks(y: np.ndarray, fraction: float = 0.15) -> int:
    """Local maxima of the waveform ``y`` at least ``fraction`` of its maximum high and as
    prominent: the distinct echoes of one pixel (the double peaks of Eq. 29 where it sees
    surfaces at two depths)."""
    from scipy import signal  # noqa: PLC0415  (scipy.signal: loaded on first use)

    top = float(np.max(y)) if len(y) else 0.0
    if top <= 0:
        return 0
    peaks, _ = signal.find_peaks(y, height=fraction * top, prominence=fraction * top)
    return len(peaks)


@dataclass(kw_only=True)
class Result:
    """One flash: the point cloud, per-pixel products and the stage timings.

    echo, receiver, detection : the outputs of those stages, per lit pixel (aligned with
    ``echo.pixel``); background : the background light per pixel; hits, rays : the ray cast;
    timings_s : seconds per stage (0 = cached).
    caster : the target's ray caster (the true mesh, for the quality metrics)
    extras : the optional stages' outputs computed so far, name -> output ("quality")
    """

    scene: Scene
    cloud: PointCloud
    echo: EchoStage
    background: Background
    receiver: Response
    detection: Detection
    hits: geometry.Hits
    rays: geometry.RayGrid
    timings_s: dict[str, float] = field(default_factory=dict)
    caster: geometry.RayCaster | None = None
    extras: dict[str, Any] = field(default_factory=dict)

    @property
    def quality(self) -> dict[str, Any]:
        """The imaging-quality figures (``simcore.quality``), computed on first use and kept
        (its time under ``timings_s["quality"]``)."""
        if "quality" not in self.extras:
            t0 = time.perf_counter()
            caster = self.caster if self.caster is not None else geometry.RayCaster(self.target)
            self.extras["quality"] = quality_stage.quality_metrics(
                self.cloud,
                caster,
                self.hits,
                self.scene.receive.fov_rad,
                self.scene.quality.tau_m,
                self.scene.seed,
                pixel_directions=self.rays.pixel_directions,
            )
            self.timings_s["quality"] = time.perf_counter() - t0
        return self.extras["quality"]

    @property
    def points(self) -> np.ndarray:
        return self.cloud.points

    @property
    def attributes(self) -> dict[str, np.ndarray]:
        return self.cloud.attributes

    @property
    def target(self) -> TargetModel:
        return self.echo.model

    @property
    def pixels(self) -> int:
        return self.rays.pixels

    def _image(self, values, fill) -> np.ndarray:
        img = np.full(self.pixels**2, fill, dtype=np.float64)
        img[self.echo.pixel] = values
        return img.reshape(self.pixels, self.pixels)

    @property
    def range_image_m(self) -> np.ndarray:
        """(pixels, pixels) measured range of each pixel's target point, NaN where none."""
        return self._image(self.detection.range_m, np.nan)

    @property
    def peak_power_image_w(self) -> np.ndarray:
        """(pixels, pixels) band-limited peak received power, 0 where no echo."""
        return self._image(self.receiver.peak_power_w, 0.0)

    @property
    def visible_faces(self) -> np.ndarray:
        return self.hits.visible_faces

    def waveform(self, row: int, col: int) -> Waveform:
        """The echo of pixel (row, col): raw and band-limited power, timing marks, threshold."""
        n = self.pixels
        if not (0 <= row < n and 0 <= col < n):
            raise IndexError(f"pixel ({row}, {col}) is outside the {n} x {n} array")
        e, d = self.echo, self.detection
        per_pixel = getattr(d, "threshold_pixel_w", None)
        threshold_w = d.threshold_w if per_pixel is None else float(per_pixel[row * n + col])
        background_w = float(self.background.power_w[row, col])
        i = np.searchsorted(e.pixel, row * n + col)
        if i >= len(e.pixel) or e.pixel[i] != row * n + col:
            return _no_echo(row, col, threshold_w, background_w)
        energy_j = self.scene.laser.pulse_energy_j
        t_s, raw, filt = e.waveform_per_j(int(i))
        peak_w = self.receiver.peak_power_w[i]
        t_ref_s = e.shape.t0_s + e.shape.step_s * np.arange(len(e.shape.filtered))
        keep = (t_ref_s >= e.shape.t_start_s) & (t_ref_s <= e.shape.t_end_s)
        return Waveform(
            row=row,
            col=col,
            t_s=t_s,
            power_w=raw * energy_j,
            filtered_w=filt * energy_j,
            emitted_t_s=t_ref_s[keep],
            emitted_w=e.shape.filtered[keep] * (peak_w / e.shape.peak_w_per_j),
            t_half_s=float(e.features.t_half_s[i]),
            threshold_w=threshold_w,
            range_m=float(d.range_m[i]),
            range_true_m=float(d.range_true_m[i]),
            p_detect=float(d.p_detect[i]),
            detected=bool(d.detected[i]),
            background_w=background_w,
        )

    def _background_summary(self) -> dict[str, Any]:
        """The background light's figures: median power over the lit pixels that see the
        target (0 at night), the sunlit and Earth pixels, saturated pixels, the Sun angle."""
        b = self.background
        saturated = getattr(self.detection, "saturated", None)
        return {
            "background_power_w_median": _lit_median(b.power_w, self.echo.pixel),
            "background_power_w_max": float(np.max(b.power_w)) if b.power_w.size else 0.0,
            "n_sunlit_pixels": int(np.count_nonzero(b.sunlit)),
            "n_earth_pixels": int(np.count_nonzero(b.earth)),
            "n_saturated": int(np.count_nonzero(saturated)) if saturated is not None else 0,
            "sun_angle_deg": None if np.isnan(b.sun_angle_deg) else float(b.sun_angle_deg),
            "eclipsed": bool(b.eclipsed),
        }

    def summary(self, quality: bool = True) -> dict[str, Any]:
        """The JSON summary of DESIGN.md section 3, with the imaging-quality figures under
        ``quality`` (``quality=False`` leaves them out and skips their cost)."""
        d, r = self.detection, self.receiver
        attrs = self.attributes
        n_out = int(attrs["is_outlier"].sum())
        n_hit = int(self.hits.hit_pixel_mask.sum())
        n_lit = len(self.echo.pixel)
        n_target_points = len(self.cloud) - n_out
        finite_sigma = d.range_sigma_m[d.detected]
        crossings = (
            d.n_false_expected
            if isinstance(d.n_false_per_pixel, np.ndarray)
            else d.n_false_per_pixel * self.pixels**2
        )
        return {
            "receiver_kind": self.scene.receiver.kind,
            "n_pixels": self.pixels**2,
            "n_hit_pixels": n_hit,
            "n_lit_pixels": n_lit,
            "n_points": len(self.cloud),
            "n_target_points": n_target_points,
            "n_outliers": n_out,
            # lit pixels that see the target and give no point; hit pixels outside the lit
            # spot (no echo at all) are counted on their own
            "n_dropped": n_lit - n_target_points,
            "n_unlit": n_hit - n_lit,
            "p_detect_mean": _stat(d.p_detect, np.mean),
            "p_detect_min": _stat(d.p_detect, np.min),  # the weakest lit pixel's
            "snr_median": _stat(r.snr, np.median),
            "range_sigma_m_median": _stat(finite_sigma, np.median),
            # false alarms: the points they are expected to leave in the cloud per frame (with
            # one stop, the first-stop arithmetic; docs/physics.md#false-points), the figure the
            # cloud's n_outliers is drawn from; and the noise crossings over the gate (Eq. 28),
            # more than the points wherever the stops per pixel cap them
            "n_false_expected": d.summary_figures.get("n_false_points_expected", crossings),
            "n_false_crossings_expected": crossings,
            **self._background_summary(),
            **self.detection.summary_figures,
            **({"quality": self.quality} if quality else {}),
            "timings_s": dict(self.timings_s),
            "target": {
                "name": self.target.name,
                "credit": self.target.credit,
                "parts": [
                    {k: row[k] for k in ("name", "material", "area_share", "transparent")}
                    for row in parts_table(self.target)
                ],
            },
            "scene": self.scene.to_dict(),
        }


def _lit_median(values: np.ndarray, pixel: np.ndarray) -> float:
    """Median of a per-pixel image over the lit pixels ``pixel`` (flat), 0 if none."""
    v = np.asarray(values).ravel()[pixel]
    return float(np.median(v)) if len(v) else 0.0


def _no_echo(row: int, col: int, threshold_w: float, background_w: float = 0.0) -> Waveform:
    empty = np.zeros(0)
    return Waveform(
        row=row,
        col=col,
        t_s=empty,
        power_w=empty,
        filtered_w=empty,
        emitted_t_s=empty,
        emitted_w=empty,
        t_half_s=np.nan,
        threshold_w=threshold_w,
        range_m=np.nan,
        range_true_m=np.nan,
        p_detect=0.0,
        detected=False,
        background_w=background_w,
    )


def _stat(values, fn) -> float | None:
    v = np.asarray(values)
    v = v[np.isfinite(v)]
    return float(fn(v)) if len(v) else None
