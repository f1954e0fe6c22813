"""The staged, cached imaging chain: ``Pipeline().run(scene)`` reads top to bottom through
the stages.

Each stage declares the scene fields it depends on; its cache key is those fields plus its upstream
key, so a TNR change re-runs only detection and the cloud, a pulse-energy change only the receiver
onwards (echoes are computed per joule), and a pose change everything but the target and the rays.
Cached arrays are read-only. One Pipeline per thread: it is not shared between threads.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np
from scipy import constants as sc

from . import detection, echo, geometry, materials, parallel, receiver, timing
from .pointcloud import PointCloud, assemble_cloud
from .scene import Scene, SceneError, with_overrides
from .target import TargetModel, load_target, with_materials

C = sc.c
STAGES = ("target", "rays", "hits", "echo", "receiver", "detection", "cloud")
MAX_OUTLIERS = 5_000_000  # false alarms drawn per flash at most (a TNR near 0 gives ~640/pixel)


# ----------------------------------------------------------------------------------------------
# stage outputs
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TargetStage:
    model: TargetModel
    caster: geometry.RayCaster


@dataclass(frozen=True)
class EchoStage:
    """Echoes of the pixels that receive light, per joule of pulse energy.

    pixel : (n,) flat pixel index; arrivals_s, weights : (n, K) Eq. 29-30 delays and weights;
    features : echo.EchoFeatures; material_id, facet_id : (n,) of the strongest sub-ray
    (material ids index materials.MATERIAL_NAMES).
    """

    model: TargetModel
    shape: echo.PulseShape
    dt_s: float
    cfd_delay_s: float
    pixel: np.ndarray
    arrivals_s: np.ndarray
    weights: np.ndarray
    features: echo.EchoFeatures
    material_id: np.ndarray
    facet_id: np.ndarray


@dataclass(frozen=True)
class ReceiverStage:
    model: receiver.ReceiverModel
    i_pk_a: np.ndarray  # (n,) peak signal current
    peak_power_w: np.ndarray  # (n,) band-limited peak received power
    snr: np.ndarray  # (n,) SNR_na (Eq. 18)
    sigma_pk_a: np.ndarray  # (n,) noise at the peak (Eq. 27)


@dataclass(frozen=True)
class DetectionStage:
    p_detect: np.ndarray  # (n,) Eq. 27
    detected: np.ndarray  # (n,) bool, drawn, in-gate
    range_true_m: np.ndarray  # (n,) noise-free half-max range (Eq. 31, carries the waveform bias)
    range_sigma_m: np.ndarray  # (n,) Eq. 24
    range_m: np.ndarray  # (n,) measured range (true + noise), NaN where not detected
    threshold_a: float
    n_false_per_pixel: float
    outliers: detection.Outliers


@dataclass(frozen=True)
class Waveform:
    """One pixel's echo. Times since emission [s], powers at the receiver input [W]."""

    row: int
    col: int
    t_s: np.ndarray
    power_w: np.ndarray  # unfiltered P_r(t)
    filtered_w: np.ndarray  # band-limited y(t)
    emitted_t_s: np.ndarray  # the emitted pulse, band-limited, scaled to this echo's peak
    emitted_w: np.ndarray
    t_half_s: float  # half-maximum time of y (NaN if no echo)
    threshold_w: float  # arming threshold TNR sigma_n expressed as input power
    range_m: float  # measured range, NaN if not detected
    range_true_m: float
    p_detect: float
    detected: bool


@dataclass
class Result:
    """One flash: the point cloud, per-pixel products and the stage timings."""

    scene: Scene
    cloud: PointCloud
    echo: EchoStage
    receiver: ReceiverStage
    detection: DetectionStage
    hits: geometry.Hits
    rays: geometry.RayGrid
    timings_s: dict[str, float] = field(default_factory=dict)

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
        e, d, r = self.echo, self.detection, self.receiver
        energy = self.scene.laser.pulse_energy_j
        threshold_w = d.threshold_a / r.model.responsivity_a_w
        i = np.searchsorted(e.pixel, row * n + col)
        if i >= len(e.pixel) or e.pixel[i] != row * n + col:
            empty = np.zeros(0)
            return Waveform(
                row,
                col,
                empty,
                empty,
                empty,
                empty,
                empty,
                np.nan,
                threshold_w,
                np.nan,
                np.nan,
                0.0,
                False,
            )
        t, raw, filt = echo.echo_waveform(e.shape, e.arrivals_s[i], e.weights[i], e.dt_s)
        peak = r.peak_power_w[i]
        t_ref = e.shape.t0_s + e.shape.step_s * np.arange(len(e.shape.filtered))
        keep = (t_ref >= e.shape.t_start_s) & (t_ref <= e.shape.t_end_s)
        return Waveform(
            row,
            col,
            t,
            raw * energy,
            filt * energy,
            t_ref[keep],
            e.shape.filtered[keep] * (peak / e.shape.peak_w_per_j),
            float(e.features.t_half_s[i]),
            threshold_w,
            float(d.range_m[i]),
            float(d.range_true_m[i]),
            float(d.p_detect[i]),
            bool(d.detected[i]),
        )

    def summary(self) -> dict[str, Any]:
        """The JSON summary of DESIGN.md section 3."""
        d, r = self.detection, self.receiver
        attrs = self.attributes
        n_out = int(attrs["is_outlier"].sum())
        n_hit = int(self.hits.hit_pixel_mask.sum())
        n_target_points = len(self.cloud) - n_out
        finite_sigma = d.range_sigma_m[d.detected]
        return {
            "n_pixels": self.pixels**2,
            "n_hit_pixels": n_hit,
            "n_lit_pixels": len(self.echo.pixel),
            "n_points": len(self.cloud),
            "n_target_points": n_target_points,
            "n_outliers": n_out,
            "n_dropped": n_hit - n_target_points,
            "p_detect_mean": _stat(d.p_detect, np.mean),
            "snr_median": _stat(r.snr, np.median),
            "range_sigma_m_median": _stat(finite_sigma, np.median),
            "n_false_expected": d.n_false_per_pixel * self.pixels**2,
            "timings_s": dict(self.timings_s),
            "target": {"name": self.target.name, "credit": self.target.credit},
            "scene": self.scene.to_dict(),
        }


def _stat(values, fn) -> float | None:
    v = np.asarray(values)
    v = v[np.isfinite(v)]
    return float(fn(v)) if len(v) else None


def _readonly(*arrays):
    for a in arrays:
        if isinstance(a, np.ndarray):
            a.setflags(write=False)


# ----------------------------------------------------------------------------------------------
# the stages
# ----------------------------------------------------------------------------------------------
def stage_target(scene: Scene) -> TargetStage:
    model = load_target(scene.target)
    return TargetStage(model, geometry.RayCaster(model))


def stage_rays(scene: Scene) -> geometry.RayGrid:
    return geometry.ray_grid(scene.detector.pixels, scene.receive.fov_rad, scene.fidelity.subrays)


def _pulse_constant(scene: Scene) -> float:
    """Eq. 1's a: ours (tau the FWHM) or the paper's printed 3.5."""
    return echo.A_PAPER if scene.uses("pulse_constant") else echo.A_FWHM


@lru_cache(maxsize=8)
def _beam_edge(pixels: int, fov_rad: float, theta_ill_rad: float, model: str) -> np.ndarray:
    """(pixels, pixels) bool: the edge of a flat-top or square beam crosses the pixel (its
    corners are not all lit or all dark; never for a Gaussian beam). The same for every pose."""
    gain = echo.illumination_gain(geometry.corner_directions(pixels, fov_rad), theta_ill_rad, model)
    edge = geometry.straddles((gain > 0).reshape(pixels + 1, -1))
    edge.setflags(write=False)
    return edge


def stage_hits(scene: Scene, tgt: TargetStage, rays: geometry.RayGrid) -> geometry.Hits:
    pose = geometry.target_pose(scene.pose, tgt.model.mesh.extents, tgt.model.body_from_mesh)
    fid = scene.fidelity
    lit_edge, steep_m = None, np.inf  # what refinement needs besides the mixed pixels
    if fid.refine_subrays > rays.subrays:
        lit_edge = _beam_edge(
            rays.pixels, rays.fov_rad, scene.illumination_angle_rad, scene.transmit.illumination
        )
        # a pixel whose range changes by more than half the pulse's rise time (in range) across
        # it echoes a plateau: refined (about 21 cm for 5 ns at 120 MHz)
        shape = echo.pulse_shape(
            scene.laser.pulse_width_s, _pulse_constant(scene), scene.detector.bandwidth_hz
        )
        steep_m = 0.5 * timing.rise_time_10_90_s(shape) * C / 2
    hits = geometry.cast(
        tgt.caster,
        rays,
        pose,
        fid.refine_subrays,
        fid.refine_step_m,
        fid.probe_corners,
        fid.cell_spread,
        lit_edge,
        steep_m,
    )
    for block in (hits.base, hits.refined):
        if block is not None:
            _readonly(block.range_m, block.cos_theta, block.face, block.depth_m)
    return hits


def stage_echo(scene: Scene, tgt: TargetStage, hits: geometry.Hits) -> EchoStage:
    model = with_materials(tgt.model, scene.target.materials)
    shape = echo.pulse_shape(
        scene.laser.pulse_width_s, _pulse_constant(scene), scene.detector.bandwidth_hz
    )
    dt = scene.fidelity.time_step_s or echo.default_time_step_s(
        scene.laser.pulse_width_s, scene.detector.bandwidth_hz
    )
    t_d = timing.cfd_delay_s(shape, scene.timing.cfd_delay_s)
    blocks = [_echo_block(scene, model, b, shape, dt, t_d) for b in hits.blocks()]
    pixel = np.concatenate([b["pixel"] for b in blocks])
    order = np.argsort(pixel, kind="stable")
    k_max = max(b["weights"].shape[1] for b in blocks)

    def merged(name, pad_value=0.0):
        parts = [b[name] for b in blocks]
        if parts[0].ndim == 2:  # pad the sub-ray axis to the largest K (weight 0: no light)
            parts = [
                np.pad(p, ((0, 0), (0, k_max - p.shape[1])), constant_values=pad_value)
                for p in parts
            ]
        return np.concatenate(parts)[order]

    raw = scene.uses("unfiltered_peak")
    feats = echo.EchoFeatures(
        merged("peak"), merged("t_half"), merged("slope"), merged("peak_raw") if raw else None
    )
    arrivals, weights = merged("arrivals"), merged("weights")
    _readonly(arrivals, weights)
    return EchoStage(
        model,
        shape,
        dt,
        t_d,
        pixel[order],
        arrivals,
        weights,
        feats,
        merged("material_id"),
        merged("facet_id"),
    )


def _echo_block(scene, model, block: geometry.HitBlock, shape, dt, t_d) -> dict[str, np.ndarray]:
    """Echo features of one block of pixels sampled with the same number of sub-rays."""
    rows = np.flatnonzero((block.face >= 0).any(axis=1))  # pixels that see the target
    face, range_m, cos_t = block.face[rows], block.range_m[rows], block.cos_theta[rows]
    lit_gain = echo.illumination_gain(
        block.directions[rows], scene.illumination_angle_rad, scene.transmit.illumination
    )
    hit = face >= 0
    mat = np.full(face.shape, -1, np.int64)
    mat[hit] = model.face_material_library[face[hit]]
    params = materials.parameter_table(materials.MATERIAL_NAMES)[mat[hit]]
    rho = np.zeros(face.shape)
    rho[hit] = materials.brdf(cos_t[hit], *params.T)
    weights = echo.element_weights(
        range_m,
        cos_t,
        rho,
        lit_gain,
        aperture_area_m2=np.pi * scene.receive.aperture_diameter_m**2 / 4.0,
        eta_t=scene.transmit.transmittance,
        eta_r=scene.receive.transmittance,
        ifov_rad=scene.ifov_rad,
        subrays=block.subrays,
        paper_4pi=scene.uses("eq30_4pi"),
    )
    keep = (weights > 0).any(axis=1)
    weights, face, mat, rows = weights[keep], face[keep], mat[keep], rows[keep]
    if scene.uses("eq29_one_way"):  # relief along the boresight, one way (the paper's print)
        distance = scene.pose.distance_m
        arrivals = 2.0 * distance / C + (block.depth_m[rows] - distance) / C
    else:
        arrivals = 2.0 * range_m[keep] / C
    arrivals = np.where(weights > 0, arrivals, 0.0)
    strongest = np.argmax(weights, axis=1)[:, None]
    material_id = np.take_along_axis(mat, strongest, axis=1)[:, 0]
    facet_id = np.take_along_axis(face, strongest, axis=1)[:, 0]
    if block.spread_m is not None:  # each sub-ray's cell: a pair of half echoes +- its spread
        arrivals, weights = echo.split_elements(arrivals, weights, 2.0 * block.spread_m[rows] / C)
    window = scene.fidelity.merge_window * timing.rise_time_10_90_s(shape)
    if window > 0 and arrivals.shape[1] > 2:
        arrivals, weights = echo.merge_elements(arrivals, weights, window)
    feats = echo.echo_features(
        shape,
        arrivals,
        weights,
        dt,
        t_d,
        scene.timing.cfd_fraction,
        raw_peak=scene.uses("unfiltered_peak"),
    )
    return {
        "pixel": block.pixel[rows],
        "arrivals": arrivals,
        "weights": weights,
        "peak": feats.peak_w_per_j,
        "t_half": feats.t_half_s,
        "slope": feats.cfd_slope_per_s,
        "peak_raw": feats.peak_raw_w_per_j if feats.peak_raw_w_per_j is not None else None,
        "material_id": material_id.astype(np.int32),
        "facet_id": facet_id.astype(np.int32),
    }


def stage_receiver(scene: Scene, ech: EchoStage) -> ReceiverStage:
    rx = receiver.receiver_model(
        scene.detector, scene.amplifiers, scene.laser.wavelength_m, paper_qe=scene.uses("qe_paper")
    )
    energy = scene.laser.pulse_energy_j
    peak_w = ech.features.peak_w_per_j * energy
    snr_peak_w = ech.features.peak_raw_w_per_j * energy if scene.uses("unfiltered_peak") else peak_w
    i_pk = rx.responsivity_a_w * snr_peak_w
    return ReceiverStage(rx, i_pk, peak_w, rx.snr(i_pk), rx.sigma_peak_a(i_pk))


def stage_detection(scene: Scene, ech: EchoStage, rx: ReceiverStage) -> DetectionStage:
    t = scene.timing
    rng = np.random.default_rng([scene.seed, 2024])
    sigma_n = rx.model.sigma_n_a
    threshold = t.tnr * sigma_n
    if scene.uses("eq27_paper"):
        p_d = detection.detection_probability_paper(rx.snr, t.tnr)
    else:
        p_d = detection.detection_probability(rx.i_pk_a, threshold, rx.sigma_pk_a)
    if scene.uses("eq25_risetime"):
        s_cfd = timing.sigma_cfd_paper_m(
            rx.snr, t.cfd_fraction, timing.rise_time_10_90_s(ech.shape)
        )
    else:
        s_cfd = timing.sigma_cfd_m(
            rx.snr,
            ech.features.cfd_slope_per_s,
            t.cfd_fraction,
            ech.cfd_delay_s,
            ech.shape.sigma_h_s,
        )
    sigma = timing.range_sigma_m(s_cfd, timing.sigma_quantisation_m(t.resolution_s))
    r_true = timing.range_from_half_max_m(ech.features.t_half_s, ech.shape.t_half_s)

    if scene.uses("eq28_paper"):
        n_false = detection.false_alarms_per_pixel_paper(
            t.tnr, t.range_gate_m, scene.detector.bandwidth_hz
        )
    else:
        n_false = detection.false_alarms_per_pixel(
            t.tnr, t.range_gate_m, scene.detector.bandwidth_hz
        )
    expected = n_false * scene.detector.pixels**2
    if expected > MAX_OUTLIERS:
        raise SceneError(
            f"timing.tnr = {t.tnr:g} gives {expected:.3g} expected false alarms per flash over "
            f"the {t.range_gate_m:g} m gate, more than the {MAX_OUTLIERS:,} this simulator draws; "
            "raise the TNR or shorten timing.range_gate_m"
        )

    n = len(ech.pixel)
    if scene.fidelity.noise_model == "montecarlo":
        # Section 5: noisy waveforms through the discriminator decide detections, ranges and
        # false alarms; P_d and sigma above stay the statistical model's, for comparison
        mc = _montecarlo().montecarlo_detection(rng, ech, rx.model, scene)
        drawn, r_meas, outliers = mc.detected, mc.range_m, mc.outliers
    else:  # Section 4: Eq. 27 draws the detection, Eq. 24 the range noise, Eq. 28 the outliers
        drawn = rng.random(n) < p_d
        noise = rng.standard_normal(n)
        with np.errstate(invalid="ignore"):
            r_meas = r_true + np.where(drawn, sigma * noise, 0.0)
        outliers = detection.draw_outliers(
            rng, scene.detector.pixels**2, n_false, scene.gate_center_m, t.range_gate_m
        )
    lo = max(0.0, scene.gate_center_m - t.range_gate_m / 2.0)
    hi = scene.gate_center_m + t.range_gate_m / 2.0
    detected = drawn & np.isfinite(r_meas) & (r_meas >= lo) & (r_meas <= hi)
    r_meas = np.where(detected, r_meas, np.nan)
    _readonly(p_d, detected, r_true, sigma, r_meas)
    return DetectionStage(p_d, detected, r_true, sigma, r_meas, threshold, n_false, outliers)


def _montecarlo():
    from . import montecarlo  # noqa: PLC0415  (imported only when the MC model is asked for)

    return montecarlo


def stage_cloud(rays: geometry.RayGrid, ech: EchoStage, rx: ReceiverStage, det: DetectionStage):
    k = det.detected
    return assemble_cloud(
        rays.pixel_directions,
        rays.pixels,
        ech.pixel[k],
        det.range_m[k],
        rx.peak_power_w[k],
        rx.snr[k],
        ech.material_id[k],
        ech.facet_id[k],
        det.outliers.pixel,
        det.outliers.range_m,
    )


# ----------------------------------------------------------------------------------------------
# the orchestrator
# ----------------------------------------------------------------------------------------------
def _deps(scene: Scene) -> dict[str, tuple]:
    """The scene fields each stage reads (its cache key, before the upstream keys)."""
    forms = lambda *names: tuple(scene.uses(n) for n in names)  # noqa: E731
    lz, det = scene.laser, scene.detector
    return {
        "target": (scene.target.mesh, scene.target.scale_m_per_unit, scene.target.material_map),
        "rays": (det.pixels, scene.receive.fov_rad, scene.fidelity.subrays),
        "hits": (
            scene.pose,
            scene.receive.fov_rad,
            scene.fidelity.refine_subrays,
            scene.fidelity.refine_step_m,
            scene.fidelity.probe_corners,
            scene.fidelity.cell_spread,
            scene.illumination_angle_rad,
            scene.transmit.illumination,
            scene.laser.pulse_width_s,
            scene.detector.bandwidth_hz,
            scene.uses("pulse_constant"),
        ),
        "echo": (
            lz.pulse_width_s,
            lz.divergence_rad,
            scene.transmit,
            scene.receive,
            scene.target.materials,
            det.bandwidth_hz,
            scene.fidelity.time_step_s,
            scene.fidelity.merge_window,
            scene.timing.cfd_fraction,
            scene.timing.cfd_delay_s,
            forms("pulse_constant", "eq30_4pi", "eq29_one_way", "unfiltered_peak"),
        ),
        "receiver": (
            lz.pulse_energy_j,
            lz.wavelength_m,
            det,
            scene.amplifiers,
            forms("qe_paper", "unfiltered_peak"),
        ),
        "detection": (
            scene.timing,
            scene.fidelity.noise_model,
            scene.seed,
            scene.gate_center_m,
            forms("eq25_risetime", "eq27_paper", "eq28_paper"),
        ),
        "cloud": (),
    }


class Cancelled(Exception):
    """Pipeline.run was told to stop (its result would be stale)."""


class Pipeline:
    """Runs scenes through the stages, re-running only those whose inputs changed."""

    def __init__(self):
        self._cache: dict[str, tuple[tuple, Any]] = {}

    def clear(self) -> None:
        self._cache.clear()

    def run(self, scene: Scene, should_stop: Callable[[], bool] | None = None) -> Result:
        """Run ``scene``; ``should_stop`` is asked before each stage that must compute, and a
        True answer raises :class:`Cancelled` (the cache keeps every stage finished so far)."""
        deps = _deps(scene)
        timings: dict[str, float] = {}
        keys: dict[str, tuple] = {}

        def stage(name: str, upstream: tuple[str, ...], compute):
            key = (deps[name], *(keys[u] for u in upstream))
            keys[name] = key
            cached = self._cache.get(name)
            if cached is not None and cached[0] == key:
                timings[name] = 0.0
                return cached[1]
            if should_stop is not None and should_stop():
                raise Cancelled(f"stopped before the {name} stage")
            t0 = time.perf_counter()
            value = compute()
            timings[name] = time.perf_counter() - t0
            self._cache[name] = (key, value)
            return value

        with parallel.blas_serial():
            tgt = stage("target", (), lambda: stage_target(scene))
            rays = stage("rays", (), lambda: stage_rays(scene))
            hits = stage("hits", ("target", "rays"), lambda: stage_hits(scene, tgt, rays))
            ech = stage("echo", ("hits",), lambda: stage_echo(scene, tgt, hits))
            rx = stage("receiver", ("echo",), lambda: stage_receiver(scene, ech))
            det = stage("detection", ("receiver",), lambda: stage_detection(scene, ech, rx))
            cloud = stage("cloud", ("detection",), lambda: stage_cloud(rays, ech, rx, det))
        return Result(scene, cloud, ech, rx, det, hits, rays, timings)


def simulate(scene: Scene | None = None, pipeline: Pipeline | None = None, **quick) -> Result:
    """Simulate one flash. ``quick`` takes the flat names (pitch_deg, azimuth_deg, distance_m,
    pixels, pulse_energy_j, tnr, seed) or dotted keys via ``overrides={...}``.

    >>> r = simulate(pixels=32)               # the paper scene, 32 x 32 pixels
    >>> r.summary()["n_pixels"]
    1024
    """
    overrides = quick.pop("overrides", None)
    scene = with_overrides(scene or Scene(), overrides, **quick)
    if not isinstance(scene, Scene):
        raise SceneError("simulate() expects a Scene")
    return (pipeline or Pipeline()).run(scene)
