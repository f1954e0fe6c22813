"""The same scenes rendered by Mitsuba 3 with mitransient (transient path tracing, LLVM variant).

The camera is Mitsuba's perspective camera with the array's full field of view across x: its
pixels are the array's tangent-plane pixels (the sub-ray grid of simcore.geometry.rays). The
beam is a spot light at the camera's centre, of the flat-top beam's radiant intensity and hard
edge (beam width = cutoff = half the illumination angle). The surface is a two-sided Lambertian
(Mitsuba's diffuse BSDF, flat face normals). Two pitfalls that fake discrepancies are undone:

- the camera's rays start at the near clip plane, so every path length mitransient records
  lacks ``near_clip / cos(alpha)``: added back per pixel (alpha the pixel centre's angle off the
  boresight);
- Mitsuba offsets each ray it spawns by about 1e-4 of the magnitude of the coordinates, so the
  target's centre sits at the world's origin and the camera where the sensor frame puts the
  lidar relative to it (minus the target's translation), looking along +z.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

NEAR_CLIP_M = 0.01  # [m] Mitsuba's default
VARIANT = "llvm_ad_mono"


def load_mitsuba(variant: str = VARIANT):
    """Mitsuba with ``variant`` set and mitransient's plugins registered (mitransient registers
    them only for the llvm_* and cuda_* variants)."""
    import mitsuba as mi  # here: the suite imports this module without Mitsuba

    mi.set_variant(variant)
    import mitransient  # noqa: F401  (registers transient_path and transient_hdr_film)

    return mi


def write_ply(path: Path, vertices_m: np.ndarray, faces: np.ndarray) -> None:
    """A binary PLY of the triangles (float32 positions, target at the origin)."""
    trimesh.Trimesh(vertices_m, faces, process=False).export(path)


def scene_dict(
    mi,
    ply: Path,
    side: dict,
    *,
    albedo: float,
    max_depth: int,
    spp: int,
    integrator: str,
    film: dict,
    supersample: int = 1,
) -> dict:
    """The Mitsuba scene of ``side`` (what :func:`validation.scenes.simcore_side` returns): its
    camera, beam and target. ``supersample``: each array pixel is supersample x supersample film
    pixels (summed afterwards in float64)."""
    scene = side["scene"]
    distance_m = scene.pose.distance_m
    half_beam_deg = float(np.degrees(scene.illumination_angle_rad / 2.0))
    lidar = [float(x) for x in side["lidar_mitsuba_m"]]  # the sensor frame's origin, moved
    eye = mi.ScalarTransform4f().look_at(
        origin=lidar, target=[lidar[0], lidar[1], lidar[2] + distance_m], up=[0, -1, 0]
    )
    pixels = scene.detector.pixels * supersample
    return {
        "type": "scene",
        "integrator": {"type": integrator, "max_depth": max_depth, "rr_depth": 1000},
        "sensor": {
            "type": "perspective",
            "fov": float(np.degrees(scene.receive.fov_rad)),
            "fov_axis": "x",
            "near_clip": NEAR_CLIP_M,
            "far_clip": 10.0 * distance_m,
            "to_world": eye,
            "sampler": {"type": "stratified", "sample_count": spp},
            "film": {"width": pixels, "height": pixels, "rfilter": {"type": "box"}, **film},
        },
        "beam": {
            "type": "spot",
            "to_world": eye,
            "intensity": float(side["beam_intensity"]),
            "cutoff_angle": half_beam_deg,
            "beam_width": half_beam_deg,
        },
        "target": {
            "type": "ply",
            "filename": str(ply),
            "face_normals": True,
            "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": float(albedo)}},
        },
    }


# mitransient holds the whole film's histogram whatever its crop: rows are rendered in bands whose
# film histogram fits this many bytes (float32 bins x 2 channels)
BAND_BYTES = 96 * 2**20
MAX_LANES = 2**22  # samples of one render (Dr.Jit's wavefront: about 1 GB at 2^22)
COARSE_BIN_M = 0.05  # [m] of optical path: the first pass that finds each row's path lengths
COARSE_SPP = 256  # enough that a thin part's paths show in its row's window
WINDOW_MARGIN_BINS = 3  # coarse bins added on either side of each row's window


def _mono(image) -> np.ndarray:
    return np.asarray(image, dtype=np.float64)[..., 0]


def _row_windows(mi, ply, side, *, albedo, max_depth):
    """Each row's recorded path lengths [lo, hi) [m] from a coarse pass (None: a dark row)."""
    radius = float(np.linalg.norm(side["vertices_mitsuba_m"], axis=1).max())
    d = float(np.linalg.norm(side["lidar_mitsuba_m"]))
    start = 2.0 * (d - radius) - 1.0
    reach = 2.0 * (d + radius) + 2.0 * radius * (max_depth - 2) + 1.0  # a bounce: 2 R more
    bins = int(np.ceil((reach - start) / COARSE_BIN_M))
    film = {"type": "transient_hdr_film", "temporal_bins": bins, "start_opl": start,
            "bin_width_opl": COARSE_BIN_M}  # fmt: skip
    sd = scene_dict(mi, ply, side, albedo=albedo, max_depth=max_depth, spp=COARSE_SPP,
                    integrator="transient_path", film=film)  # fmt: skip
    _, coarse = mi.render(mi.load_dict(sd), seed=1_000_003)
    windows = []
    for row in np.asarray(coarse)[..., 0]:
        occupied = np.flatnonzero(row.sum(axis=0) > 0)
        if not len(occupied):
            windows.append(None)
            continue
        first, last = occupied[0] - WINDOW_MARGIN_BINS, occupied[-1] + 1 + WINDOW_MARGIN_BINS
        windows.append((start + first * COARSE_BIN_M, start + last * COARSE_BIN_M))
    return windows


def _bands(windows, pixels, bin_m, spp):
    """Consecutive lit rows grouped so that each band's histogram fits BAND_BYTES and its
    samples MAX_LANES: [first row, last row, lo, hi]."""
    bands, current = [], None
    for r, w in enumerate(windows):
        if w is None:
            continue
        if current is not None:
            lo, hi = min(current[2], w[0]), max(current[3], w[1])
            fits = pixels * pixels * 2 * 4 * (hi - lo) / bin_m <= BAND_BYTES
            lanes = (r - current[0] + 1) * pixels * spp
            if fits and lanes <= MAX_LANES and current[1] == r - 1:
                current = [current[0], r, lo, hi]
                continue
            bands.append(current)
        current = [r, r, w[0], w[1]]
    if current is not None:
        bands.append(current)
    return bands


def _near_clip_m(scene) -> np.ndarray:
    """(n, n) the path each pixel's camera rays lack: near_clip / cos(alpha), alpha the pixel
    centre's angle off the boresight [m]."""
    n = scene.detector.pixels
    tan = (np.arange(n) - (n - 1) / 2.0) * 2.0 * np.tan(scene.receive.fov_rad / 2.0) / n
    return NEAR_CLIP_M * np.sqrt(1.0 + tan[:, None] ** 2 + tan[None, :] ** 2)


def transient(mi, side, *, spp, bin_m, albedo=1.0, max_depth=2, seed=0):
    """Each lit pixel's path-length histogram (mitransient's transient_path into its
    transient_hdr_film; box filter; ``spp`` stratified samples per pixel).

    Returns {"bins": {flat pixel: (opl_m (L,), value (L,))}, the path lengths with the near clip
    added back and the mean radiance per unit beam intensity each carries; "steady": (n, n)
    the film's steady image; "histogram_share": the histograms' sum over the steady image's
    (1 when no path fell outside the windows, to float32's accumulation); "renders", "wall_s"}.
    """
    scene = side["scene"]
    n = scene.detector.pixels
    t0 = time.perf_counter()
    near = _near_clip_m(scene)
    steady_all, hist_sum, bins = np.zeros((n, n)), np.zeros((n, n)), {}
    with tempfile.TemporaryDirectory() as tmp:
        ply = Path(tmp) / "target.ply"
        write_ply(ply, side["vertices_mitsuba_m"], side["faces"])
        windows = _row_windows(mi, ply, side, albedo=albedo, max_depth=max_depth)
        bands = _bands(windows, n, bin_m, spp)
        for r0, r1, lo, hi in bands:
            count = int(np.ceil((hi - lo) / bin_m))
            rows = r1 - r0 + 1
            film = {"type": "transient_hdr_film", "temporal_bins": count, "start_opl": lo,
                    "bin_width_opl": bin_m, "crop_offset_x": 0, "crop_offset_y": r0,
                    "crop_width": n, "crop_height": rows}  # fmt: skip
            sd = scene_dict(mi, ply, side, albedo=albedo, max_depth=max_depth, spp=spp,
                            integrator="transient_path", film=film)  # fmt: skip
            steady, hist = mi.render(mi.load_dict(sd), seed=seed)
            steady, hist = _mono(steady), np.asarray(hist)[:rows, :, :, 0]  # a crop's rows first
            steady_all[r0 : r1 + 1] = steady
            hist_sum[r0 : r1 + 1] = hist.sum(axis=2, dtype=np.float64)
            centres = lo + (np.arange(count) + 0.5) * bin_m
            for i, j in zip(*np.nonzero(steady > 0), strict=True):
                keep = hist[i, j] > 0
                bins[(r0 + i) * n + j] = (
                    centres[keep] + near[r0 + i, j],
                    hist[i, j][keep].astype(np.float64),
                )
    lit = steady_all > 0
    share = float(hist_sum[lit].sum() / steady_all[lit].sum()) if lit.any() else 1.0
    return {"bins": bins, "steady": steady_all, "histogram_share": share,
            "renders": len(bands) + 1, "wall_s": time.perf_counter() - t0}  # fmt: skip


def steady(mi, side, *, supersample, spp, albedo=1.0, max_depth=2, seed=0):
    """(n, n) each array pixel's mean radiance per unit beam intensity: Mitsuba's path tracer
    into an hdrfilm of supersample x supersample film pixels per array pixel, ``spp``
    stratified samples each (few, so that float32 sums them to 1e-7), summed in float64.

    Returns {"radiance": (n, n), "renders", "wall_s"}."""
    scene = side["scene"]
    n = scene.detector.pixels
    m = supersample
    t0 = time.perf_counter()
    out = np.zeros((n, n))
    rows = max(1, MAX_LANES // (n * m * m * spp))  # array rows per render
    renders = 0
    with tempfile.TemporaryDirectory() as tmp:
        ply = Path(tmp) / "target.ply"
        write_ply(ply, side["vertices_mitsuba_m"], side["faces"])
        for r0 in range(0, n, rows):
            r1 = min(n, r0 + rows)
            film = {
                "type": "hdrfilm",
                "pixel_format": "luminance",
                "crop_offset_x": 0,
                "crop_offset_y": r0 * m,
                "crop_width": n * m,
                "crop_height": (r1 - r0) * m,
            }
            sd = scene_dict(mi, ply, side, albedo=albedo, max_depth=max_depth, spp=spp,
                            integrator="path", film=film, supersample=m)  # fmt: skip
            image = np.asarray(mi.render(mi.load_dict(sd), seed=seed), dtype=np.float64)
            image = image.reshape((r1 - r0) * m, n * m)
            out[r0:r1] = image.reshape(r1 - r0, m, n, m).mean(axis=(1, 3))
            renders += 1
    return {"radiance": out, "renders": renders, "wall_s": time.perf_counter() - t0}
