"""The echo stage (Eqs. 29-30): per-pixel sub-ray delays and weights, and the features of each
pixel's band-limited echo, per joule of pulse energy. What it hands the receiver is
:class:`EchoStage` (features for every lit pixel, full waveforms on demand).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import geometry, materials, parallel
from ..constants import C
from ..pulse import PulseShape, cfd_delay_s, default_time_step_s, scene_pulse_shape
from ..scene import Scene, SceneError
from ..stage import Stage, readonly
from ..target import TargetModel, with_materials
from .elements import element_weights, illumination_gain, merge_elements, split_elements
from .features import EchoFeatures, echo_features, sample_echoes


@dataclass(frozen=True, kw_only=True)
class EchoStage:
    """What the echo stage hands a receiver: the echoes of the pixels that receive light, per
    joule of pulse energy (received power scales linearly with it).

    model : the target with the scene's materials
    shape : the emitted pulse and its band-limited reference copy (tables per joule)
    dt_s : waveform time step [s]
    cfd_delay_s : CFD delay t_d in force (Eq. 19) [s]
    pixel : (n,) int64 flat index (row * pixels + col) of each lit pixel, ascending
    arrivals_s : (n, K) two-way delay of each element (Eq. 29) [s]; 0 where its weight is 0
    weights : (n, K) Eq. 30 weight of each element [1] (0 = no light)
    features : per-pixel band-limited features (peak [W/J], half-maximum time, CFD slope)
    material_id, facet_id : (n,) int32 of each pixel's strongest element (material ids index
        ``materials.MATERIAL_NAMES``)
    """

    model: TargetModel
    shape: PulseShape
    dt_s: float
    cfd_delay_s: float
    pixel: np.ndarray
    arrivals_s: np.ndarray
    weights: np.ndarray
    features: EchoFeatures
    material_id: np.ndarray
    facet_id: np.ndarray

    def waveform_per_j(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Lit pixel ``i``'s full echo on its own window: t_s (L,) [s], unfiltered P_r (L,) and
        band-limited y (L,) [W/J]."""
        return echo_waveform(self.shape, self.arrivals_s[i], self.weights[i], self.dt_s)


def echo_waveform(shape: PulseShape, arrivals_s, weights, dt: float):
    """One pixel's full echo on its own window, for display and export.

    arrivals_s, weights : (K,) -- one pixel's sub-ray delays [s] and weights
    Returns t_s (L,), raw P_r per joule (L,), band-limited y per joule (L,).
    """
    arrivals = np.asarray(arrivals_s, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    has = weights > 0
    if not has.any():
        return np.zeros(0), np.zeros(0), np.zeros(0)
    a, w = arrivals[has][None, :], weights[has][None, :]
    t = np.arange(a.min() + shape.t_start_s, a.max() + shape.t_end_s, dt)
    raw, filt = (
        sample_echoes(shape, p, a, w, t[:1], dt, len(t))[0] for p in (shape.raw, shape.filtered)
    )
    return t, raw, filt


def stage_echo(scene: Scene, tgt: geometry.TargetStage, hits: geometry.Hits) -> EchoStage:
    """Every lit pixel's elements and echo features, blocks of equal sub-ray counts merged."""
    model = with_materials(tgt.model, scene.target.materials)
    shape = scene_pulse_shape(scene)
    dt_s = scene.fidelity.time_step_s or default_time_step_s(
        scene.laser.pulse_width_s, scene.detector.bandwidth_hz
    )
    t_d_s = cfd_delay_s(shape, scene.timing.cfd_delay_s)
    check_echo_cost(shape, dt_s, int(np.count_nonzero(hits.hit_pixel_mask)))
    blocks = [_echo_block(scene, model, b, shape, dt_s, t_d_s) for b in hits.blocks()]
    pixel = np.concatenate([b["pixel"] for b in blocks])
    # one block of ascending pixels (no refinement) is taken as it is: no copies
    order = None if len(blocks) == 1 else np.argsort(pixel, kind="stable")
    k_max = max(b["weights"].shape[1] for b in blocks)

    def merged(name, pad_value=0.0):
        parts = [b[name] for b in blocks]
        if order is None:
            return parts[0]
        if name in ("arrivals", "weights"):  # pad the element axis to the largest (weight 0)
            parts = [
                np.pad(p, ((0, 0), (0, k_max - p.shape[1])), constant_values=pad_value)
                for p in parts
            ]
        return np.concatenate(parts)[order]

    raw = scene.uses("unfiltered_peak")
    feats = EchoFeatures(
        peak_w_per_j=merged("peak"),
        t_half_s=merged("t_half"),
        cfd_slope_per_s=merged("slope"),
        peak_raw_w_per_j=merged("peak_raw") if raw else None,
        cfd_shot_level=merged("level"),
    )
    arrivals, weights = merged("arrivals"), merged("weights")
    readonly(arrivals, weights)
    return EchoStage(
        model=model,
        shape=shape,
        dt_s=dt_s,
        cfd_delay_s=t_d_s,
        pixel=pixel if order is None else pixel[order],
        arrivals_s=arrivals,
        weights=weights,
        features=feats,
        material_id=merged("material_id"),
        facet_id=merged("facet_id"),
    )


# refused above: samples of the lit pixels' echo windows (the default frame's are about 5e6; 2.4e9,
# detector.bandwidth_hz = 1e3 at 64 px, ran 48 s in the echo kernel)
MAX_ECHO_SAMPLES = 2**28


def echo_samples(shape: PulseShape, dt_s: float, n_lit: int) -> float:
    """Samples of ``n_lit`` single-surface echo windows at ``dt_s`` [1]: each spans the band-limited
    pulse's table (from 1e-5 of its peak before it to 1e-4 after)."""
    return float(n_lit) * (shape.t_end_s - shape.t_start_s) / dt_s


def check_echo_cost(shape: PulseShape, dt_s: float, n_lit: int) -> None:
    """Refuse (SceneError, one line naming the keys) a frame whose echo windows would hold more
    than MAX_ECHO_SAMPLES samples, before any is computed: a band limit much wider than the step
    (detector.bandwidth_hz far below 1 / laser.pulse_width_s)."""
    samples = echo_samples(shape, dt_s, n_lit)
    if samples > MAX_ECHO_SAMPLES:
        raise SceneError(
            f"detector.bandwidth_hz = {1.0 / (4.0 * np.sqrt(np.pi) * shape.sigma_h_s):g} Hz with "
            f"laser.pulse_width_s = {shape.tau_s:g} s at a time step of {dt_s:.3g} s: the "
            f"{n_lit} lit pixels' echo windows would hold {samples:.2g} samples (at most "
            f"{MAX_ECHO_SAMPLES:.2g}): give a detector.bandwidth_hz nearer 1 / (2 "
            "laser.pulse_width_s), a coarser fidelity.time_step_s or fewer detector.pixels"
        )


def any_per_row(mask: np.ndarray) -> np.ndarray:
    """(n,) bool: each row of ``mask`` ((n, K) bool) has a True; ``mask.any(axis=1)``, by one
    pass per column (numpy's reduction along a short axis took 1.3 ms for 65,536 rows of 4)."""
    out = mask[:, 0].copy() if mask.shape[1] else np.zeros(len(mask), bool)
    for k in range(1, mask.shape[1]):
        out |= mask[:, k]
    return out


# Lit pixels per chunk of the element work below which a block's elements are made on the calling
# thread alone (the numpy passes of a few thousand pixels take well under a millisecond)
ELEMENT_CHUNK_PIXELS = 4096


def _echo_block(
    scene, model, block: geometry.HitBlock, shape, dt_s, cfd_delay_s
) -> dict[str, np.ndarray]:
    """Echo features of one block of pixels sampled with the same number of sub-rays: the
    elements of chunks of its lit pixels on the frame's threads (numpy releases the GIL over
    these arrays; each pixel's figures do not depend on the chunks), then the features of all."""
    rows = np.flatnonzero(any_per_row(block.face >= 0))  # pixels that see the target
    parts = min(parallel.threads(), len(rows) // ELEMENT_CHUNK_PIXELS) or 1
    bounds = np.linspace(0, len(rows), parts + 1).astype(int)
    # each part's material (its index in materials.MATERIAL_NAMES), the faces' looked up in the
    # chunks: model.face_material_library maps every face, 0.4 ms a frame on this thread alone
    part_material = model.part_material_library
    face_part = np.asarray(model.face_part)
    chunks = parallel.map_threads(
        lambda part: _elements(scene, (part_material, face_part), block, part, shape),
        [rows[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)],
    )
    width = max(c["weights"].shape[1] for c in chunks)
    for c in chunks:  # merged chunks of fewer bins: padded (weight 0 at the pixel's first arrival)
        extra = width - c["weights"].shape[1]
        if extra:
            c["weights"] = np.pad(c["weights"], ((0, 0), (0, extra)))
            c["arrivals"] = np.hstack([c["arrivals"], np.repeat(c["t0"][:, None], extra, axis=1)])

    def joined(name):
        return chunks[0][name] if len(chunks) == 1 else np.concatenate([c[name] for c in chunks])

    arrivals, weights = joined("arrivals"), joined("weights")
    feats = echo_features(
        shape,
        arrivals,
        weights,
        dt_s,
        cfd_delay_s,
        scene.timing.cfd_fraction,
        raw_peak=scene.uses("unfiltered_peak"),
    )
    return {
        "pixel": joined("pixel"),
        "arrivals": arrivals,
        "weights": weights,
        "peak": feats.peak_w_per_j,
        "t_half": feats.t_half_s,
        "slope": feats.cfd_slope_per_s,
        "peak_raw": feats.peak_raw_w_per_j if feats.peak_raw_w_per_j is not None else None,
        "level": feats.cfd_shot_level,
        "material_id": joined("material_id"),
        "facet_id": joined("facet_id"),
    }


def _elements(scene, materials_of, block: geometry.HitBlock, rows, shape) -> dict[str, np.ndarray]:
    """The echo elements of lit pixels ``rows`` of ``block`` (Eqs. 29-30): the pixels that
    receive light (pixel), their elements' delays and weights (arrivals, weights: (n, M), split
    by cell spread and merged within the window), their strongest element's material and facet
    (material_id, facet_id) and each pixel's first arrival (t0, the delay of unused elements).
    ``materials_of``: each part's material index and each face's part."""
    face, range_m, cos_t = block.face[rows], block.range_m[rows], block.cos_theta[rows]
    lit_gain = illumination_gain(
        block.directions[rows], scene.illumination_angle_rad, scene.transmit.illumination
    )
    hit = face >= 0
    mat = np.full(face.shape, -1, np.int64)
    part_material, face_part = materials_of  # (n_parts,) and (n_faces,)
    mat[hit] = part_material[face_part[face[hit]]]
    params = materials.parameter_table(materials.MATERIAL_NAMES)[mat[hit]]
    rho = np.zeros(face.shape)
    rho[hit] = materials.brdf(cos_t[hit], *params.T)
    weights = element_weights(
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
    keep = any_per_row(weights > 0)
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
        arrivals, weights = split_elements(arrivals, weights, 2.0 * block.spread_m[rows] / C)
    window = scene.fidelity.merge_window * shape.rise_time_10_90_s
    t0 = np.zeros(len(rows))
    if window > 0 and arrivals.shape[1] > 2:
        t0 = np.where(weights > 0, arrivals, np.inf).min(axis=1) if len(rows) else t0
        arrivals, weights = merge_elements(arrivals, weights, window)
    return {
        "pixel": block.pixel[rows],
        "arrivals": arrivals,
        "weights": weights,
        "t0": t0,
        "material_id": material_id.astype(np.int32),
        "facet_id": facet_id.astype(np.int32),
    }


def _reads(s: Scene) -> tuple:
    """Every scene value the echo stage reads (the target, pose and pixels come through hits)."""
    return (
        s.laser.pulse_width_s,
        s.laser.divergence_rad,
        s.transmit,
        # the optics the echo scales with (its filter acts on the background light only)
        s.receive.aperture_diameter_m,
        s.receive.transmittance,
        s.receive.fov_rad,
        s.target.materials,
        s.detector.bandwidth_hz,
        s.detector.pixels,
        s.pose.distance_m,
        s.fidelity.time_step_s,
        s.fidelity.merge_window,
        s.timing.cfd_fraction,
        s.timing.cfd_delay_s,
        tuple(s.uses(f) for f in ("pulse_constant", "eq30_4pi", "eq29_one_way", "unfiltered_peak")),
    )


ECHO = Stage(name="echo", upstream=("target", "hits"), reads=_reads, compute=stage_echo)
