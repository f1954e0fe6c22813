"""Where the Gaussian waveform Monte Carlo departs from the photon-level one
(docs/physics.md#mcintyre): P_d against photoelectrons per pulse and false alarms per pixel
against TNR, both models on the same single-surface echoes, for the default (thermal-limited)
receiver and a quiet one whose single photoelectron is about one sigma_n high.

    .venv/bin/python scripts/photon_vs_gaussian.py [--pixels 3000] [--json out.json]

Prints a table; docs/simulation.md quotes it.
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

import simcore
from simcore.constants import C, H
from simcore.receivers.lm_apd import apd, montecarlo
from simcore.receivers.lm_apd.montecarlo.photon import PhotonNoise

QUIET = {"detector.gain_from": "gain", "detector.gain": 100.0, "detector.load_ohm": 1e5}
PE = (1, 3, 10, 30, 100)
TNRS = (3.0, 4.0, 5.0, 6.0)


def run(scene, photon: bool, pe: float, tnr: float, n: int, seed: int):
    """Detected fraction of n echo pixels and false alarms per noise-only pixel (30 m gate)."""
    rx = apd.receiver_model(scene.detector, scene.amplifiers, scene.laser.wavelength_m)
    d = scene.detector
    hv = H * C / scene.laser.wavelength_m
    w = pe * hv / (d.quantum_efficiency * scene.laser.pulse_energy_j)  # sum of weights [1/J]
    arrivals = np.full((n, 1), 2 * scene.pose.distance_m / C)
    weights = np.full((n, 1), w)
    options = {"photon": PhotonNoise(d.excess_noise_k, d.dark_bulk_a)} if photon else {}
    res = montecarlo.scene_gate(
        np.random.default_rng(seed),
        scene,
        rx,
        arrivals,
        weights,
        tnr=tnr,
        gate_m=30.0,
        n_pixels_total=2 * n,
        first_stop=True,
        **options,
    )
    return float(res.detected.mean()), res.n_false_alarms / (2 * n - res.detected.sum())


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--pixels", type=int, default=3000)
    parser.add_argument("--json", default="")
    args = parser.parse_args()
    out = {}
    for name, overrides in (("default", {}), ("quiet", QUIET)):
        scene = simcore.with_overrides(simcore.Scene(), overrides)
        rx = apd.receiver_model(scene.detector, scene.amplifiers, scene.laser.wavelength_m)
        print(
            f"\n{name} receiver: M = {rx.gain:.3g}, F = {rx.excess_noise:.3g}, "
            f"sigma_n = {rx.sigma_n_a:.3g} A"
        )
        for tnr in TNRS:
            for pe in PE:
                g = run(scene, False, pe, tnr, args.pixels, 1)
                p = run(scene, True, pe, tnr, args.pixels, 1)
                out[f"{name} tnr={tnr} pe={pe}"] = {"gaussian": g, "photon": p}
                se = math.sqrt(max(g[0] * (1 - g[0]), 1e-4) / args.pixels)
                print(
                    f"TNR {tnr:.0f} pe {pe:4d}: P_d gaussian {g[0]:.3f} photon {p[0]:.3f} "
                    f"(se {se:.3f}); false alarms/pixel/30 m gaussian {g[1]:.2e} "
                    f"photon {p[1]:.2e}"
                )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
