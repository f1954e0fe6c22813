"""``python -m validation``: the echo stage checked against Mitsuba 3 with mitransient
(``make validate``; the figures of docs/validation.md, written as JSON).

Each scene goes through lmapd-sim's chain (hits, echo) and through Mitsuba: a steady render for
the per-pixel energies (16 x 16 film pixels per array pixel, 16 stratified samples each) and a
transient render for the echoes (1,024 stratified samples per pixel into path-length histograms).
Nothing of simcore's enters Mitsuba's side but the scene: the posed mesh, the optics and the
pixel grid; simcore's band-limited pulse and its feature extraction turn Mitsuba's histogram into
the half-maximum time that the echo stage reports, so that those times compare like for like.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from simcore.echo.features import echo_features

from . import compare, render
from .scenes import DISTANCE_M, PIXELS, scenes, simcore_side

OUT = Path(__file__).resolve().parent.parent / "docs" / "data" / "validation.json"
PLATE_BIN_M = 0.0005  # [m] of optical path per histogram bin on the plates (1.7 ps)
MRO_BIN_M = 0.002  # [m] on the MRO (6.7 ps)
TRANSIENT_SPP = 1024
SUPERSAMPLE, STEADY_SPP = 16, 16
MULTI_BOUNCE_DEPTH = 16  # path vertices of the multi-bounce render (item: a second bounce)
PS = 1e12


def _ps(stats: dict) -> dict:
    return {k: (v * PS if isinstance(v, float) and k != "n" else v) for k, v in stats.items()}


def mitsuba_echoes(side: dict, bins: dict, n: int):
    """Per-pixel mean delay (n, n) [s] and half-maximum time (n, n) [s] of Mitsuba's
    histograms, the latter through simcore's band-limited pulse and feature extraction."""
    mean = np.full(n * n, np.nan)
    t_half = np.full(n * n, np.nan)
    pixels = sorted(bins)
    width = max(len(bins[p][0]) for p in pixels)
    arrivals = np.zeros((len(pixels), width))
    weights = np.zeros((len(pixels), width))
    for i, p in enumerate(pixels):
        opl, value = bins[p]
        arrivals[i, : len(opl)] = opl / compare.C
        arrivals[i, len(opl) :] = opl[0] / compare.C
        weights[i, : len(opl)] = value * side["radiance_scale"]
        mean[p] = compare.moments(opl / compare.C, value)[0]
    scene = side["scene"]
    feats = echo_features(
        side["shape"], arrivals, weights, side["dt_s"], side["cfd_delay_s"],
        scene.timing.cfd_fraction,
    )  # fmt: skip
    t_half[pixels] = feats.t_half_s
    return mean.reshape(n, n), t_half.reshape(n, n)


# simcore's fidelities compared with the one Mitsuba render of each scene: the defaults (2 x 2
# sub-rays), and the app's and the reference presets
FIDELITIES = {"default": {}, "interactive": {"preset": "interactive"},
              "reference": {"preset": "reference"}}  # fmt: skip


def compare_side(name: str, side: dict, energy_mi, tr: dict) -> dict:
    """The figures of one simcore fidelity against Mitsuba's renders of the scene."""
    n = side["scene"].detector.pixels
    energy_sc = side["energy_per_j"]
    mean_mi, t_half_mi = mitsuba_echoes(side, tr["bins"], n)
    both = (energy_sc > 0) & (energy_mi > 0)
    inner = compare.interior(both)
    d_mean = mean_mi - side["mean_delay_s"]
    d_half = t_half_mi - side["t_half_s"]
    opl = np.concatenate([b[0] for b in tr["bins"].values()])
    value = np.concatenate([b[1] for b in tr["bins"].values()])
    whole_mi = compare.moments(opl / compare.C, value)
    whole_sc = compare.moments(side["element_delay_s"], side["element_weight"])
    out = {
        "subrays": side["scene"].fidelity.subrays,
        "refine_subrays": side["scene"].fidelity.refine_subrays,
        "lit": compare.lit_pixels(energy_sc, energy_mi),
        "interior_pixels": int(inner.sum()),
        "energy_interior": compare.relative(energy_mi, energy_sc, inner),
        "energy_lit_both": compare.relative(energy_mi, energy_sc, both),
        "energy_total_ratio": float(energy_mi.sum() / energy_sc.sum()),
        "mean_delay_ps": {
            "interior": _ps(compare.spread(d_mean[inner])),
            "lit_both": _ps(compare.spread(d_mean[both])),
        },  # fmt: skip
        "t_half_ps": {
            "interior": _ps(compare.spread(d_half[inner])),
            "lit_both": _ps(compare.spread(d_half[both])),
        },  # fmt: skip
        "whole_echo": {
            "simcore_rms_ps": whole_sc[1] * PS,
            "mitsuba_rms_ps": whole_mi[1] * PS,
            "mean_delay_difference_ps": (whole_mi[0] - whole_sc[0]) * PS,
        },
    }
    if "plate" in name:
        quad = compare.plate_echo(side["vertices_m"])
        out["whole_echo"]["closed_form_rms_ps"] = quad[1] * PS
        out["whole_echo"]["closed_form_mean_minus_simcore_ps"] = (quad[0] - whole_sc[0]) * PS
    return out


def check_scene(mi, name: str, keys: dict, bin_m: float) -> dict:
    """One scene: Mitsuba's renders, and each fidelity of simcore against them."""
    side = simcore_side(keys)
    steady = render.steady(mi, side, supersample=SUPERSAMPLE, spp=STEADY_SPP)
    energy_mi = steady["radiance"] * side["radiance_scale"]
    tr = render.transient(mi, side, spp=TRANSIENT_SPP, bin_m=bin_m)
    out = {
        "keys": {k: v for k, v in keys.items() if k not in ("target.materials", "target.mesh")},
        "target": "plate" if "plate" in name else keys["target.mesh"],
        "histogram_share": tr["histogram_share"],
        "histogram_bin_ps": bin_m / compare.C * PS,
        "mitsuba_renders": steady["renders"] + tr["renders"],
        "mitsuba_wall_s": steady["wall_s"] + tr["wall_s"],
        "fidelity": {},
    }
    if "plate" in name:
        out["plate_corners_m"] = np.round(side["vertices_m"], 6).tolist()
        out["incidence_deg"] = float(name.split("_")[1].removesuffix("deg"))
    for fidelity, extra in FIDELITIES.items():
        this = side if not extra else simcore_side({**keys, **extra})
        out["fidelity"][fidelity] = compare_side(name, this, energy_mi, tr)
    return out


def multi_bounce(mi, keys: dict, albedos=(1.0, 0.5)) -> dict:
    """Energy of the renders with more bounces over the single-bounce one, per albedo (steady
    renders; Mitsuba's path tracer to 3 path vertices: exactly two bounces, and to
    MULTI_BOUNCE_DEPTH)."""
    side = simcore_side(keys)
    out = {}
    for albedo in albedos:
        one = render.steady(mi, side, supersample=SUPERSAMPLE, spp=STEADY_SPP, albedo=albedo)
        lit = one["radiance"] > 0
        figures = {}
        for depth in (3, MULTI_BOUNCE_DEPTH):
            many = render.steady(mi, side, supersample=SUPERSAMPLE, spp=STEADY_SPP,
                                 albedo=albedo, max_depth=depth)  # fmt: skip
            ratio = many["radiance"][lit] / one["radiance"][lit]
            figures[f"depth_{depth}"] = {
                "energy_ratio": float(many["radiance"].sum() / one["radiance"].sum()),
                "pixel_ratio_minus_1": compare.spread(ratio - 1.0),
                "dark_in_single_lit_in_multi": int(((many["radiance"] > 0) & ~lit).sum()),
            }
        out[f"{albedo:g}"] = figures
    return out


def machine() -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": cpu, "cpus": os.cpu_count(), "python": platform.python_version()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m validation", description=__doc__)
    parser.add_argument("--out", type=Path, default=OUT, help="the JSON written (%(default)s)")
    parser.add_argument("--only", nargs="*", default=None, help="scene names (default: all)")
    parser.add_argument("--no-multi-bounce", action="store_true",
                        help="leave out the multi-bounce energy on the MRO")  # fmt: skip
    args = parser.parse_args(argv)
    from importlib import metadata

    mi = render.load_mitsuba()
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    results = {}
    for name, keys in scenes().items():
        if args.only and name not in args.only:
            continue
        bin_m = MRO_BIN_M if name == "mro" else PLATE_BIN_M
        print(f"validation: {name} ...", file=sys.stderr, flush=True)
        results[name] = check_scene(mi, name, keys, bin_m)
    out = {
        "date_utc": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M"),
        "machine": machine(),
        "load_average_before": load,
        "mitsuba": metadata.version("mitsuba"),
        "mitransient": metadata.version("mitransient"),
        "variant": render.VARIANT,
        "distance_m": DISTANCE_M,
        "pixels": PIXELS,
        "transient_spp": TRANSIENT_SPP,
        "steady_samples_per_pixel": SUPERSAMPLE**2 * STEADY_SPP,
        "scenes": results,
    }
    if not args.no_multi_bounce and (not args.only or "mro" in args.only):
        print("validation: multi-bounce on the MRO ...", file=sys.stderr, flush=True)
        out["multi_bounce_mro"] = multi_bounce(mi, scenes()["mro"])
    out["wall_s"] = time.perf_counter() - t0
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    print(f"validation: wrote {args.out} ({out['wall_s']:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
