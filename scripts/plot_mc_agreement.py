"""Statistical model (Eqs. 24-27, ours) against the waveform Monte Carlo
(docs/physics.md#monte-carlo).

Writes docs/img/mc_agreement.png with two panels -- P_d vs TNR for several SNR (Eq. 27 curves,
MC points with binomial error bars) and range sigma vs SNR (Eq. 24 with Eq. 25 per sample, the
default: each CFD sample's own shot noise, and with the paper's equal-noise form; MC points) --
and prints the agreement figures. False alarms against TNR (Rice, the paper's forms, MC points)
are drawn in one place, the reproduction's Figure 9 (``lmapd reproduce``:
fig09_detection.png, with the Monte Carlo / Rice ratios in its report.json).

    .venv/bin/python scripts/plot_mc_agreement.py [--out docs/img/mc_agreement.png] [--quick]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # support.mc_scene
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from scipy import constants as sc
from support.mc_scene import DT, K_ATT, RX, RX_THERMAL, SCENE, SHAPE, T_D, T_T, E

from simcore import echo
from simcore.receivers.lm_apd import detection, montecarlo, timing

C = sc.c


def i_pk_for_snr(snr, rx):
    """Band-limited peak current with SNR_na (Eq. 18) = snr [A]."""
    return rx.peak_current_for_snr(snr)


def gate(rng, arrivals, weights, rx, tnr, gate_m, n_total=None, **kw):
    return montecarlo.scene_gate(
        rng, SCENE, rx, arrivals, weights, tnr=tnr, gate_m=gate_m, n_pixels_total=n_total, **kw
    )


def single_surface(snrs, n_each, rng, rx):
    i_pk = np.repeat(i_pk_for_snr(snrs, rx), n_each)
    weights = (i_pk / (rx.responsivity_a_w * E * SHAPE.peak_w_per_j))[:, None]
    arrivals = 2.0 * rng.uniform(498.0, 502.0, size=(len(i_pk), 1)) / C
    return arrivals, weights, i_pk


def pd_panel(ax, quick):
    snrs = (3.0, 4.5, 6.0, 7.5)
    tnrs = np.arange(2.0, 8.01, 1.0 if quick else 0.5)
    n_each = 800 if quick else 3000
    rng = np.random.default_rng(2024)
    worst = (0.0, None)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    p_mc = np.zeros((len(snrs), len(tnrs)))
    for j, tnr in enumerate(tnrs):
        arrivals, weights, _ = single_surface(snrs, n_each, rng, RX)
        res = gate(rng, arrivals, weights, RX, tnr, 10.0)
        p_mc[:, j] = res.detected.reshape(len(snrs), n_each).mean(axis=1)
    tnr_fine = np.linspace(1.5, 8.5, 300)
    for k, snr in enumerate(snrs):
        i_pk = float(i_pk_for_snr(snr, RX))
        p27 = detection.detection_probability(i_pk, tnr_fine * RX.sigma_n_a, RX.sigma_peak_a(i_pk))
        ax.plot(tnr_fine, p27, color=colors[k], lw=1.5, label=f"Eq. 27, SNR {snr:g}")
        err = np.sqrt(np.maximum(p_mc[k] * (1 - p_mc[k]), 1.0 / n_each) / n_each)
        ax.errorbar(tnrs, p_mc[k], yerr=2 * err, fmt="o", ms=4, color=colors[k], capsize=2)
        p27_pts = detection.detection_probability(i_pk, tnrs * RX.sigma_n_a, RX.sigma_peak_a(i_pk))
        diff = np.abs(p_mc[k] - p27_pts)
        for j in range(len(tnrs)):
            if diff[j] > worst[0]:
                worst = (float(diff[j]), (snr, float(tnrs[j]), p_mc[k, j], p27_pts[j]))
    ax.plot([], [], "o", color="0.3", label="MC points (bars: 2 binomial sigma)")
    ax.set_xlabel("TNR = V_T / sigma_n  [1]")
    ax.set_ylabel("detection probability P_d  [1]")
    ax.set_title(f"P_d: single-surface pixels, {n_each} per point")
    ax.set_ylim(-0.03, 1.03)
    ax.set_xlim(0.5, 8.7)  # room for the legend at the lower left
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    return worst


def robust_sigma(x):
    x = x[np.isfinite(x)]
    return 1.4826 * np.median(np.abs(x - np.median(x))), len(x)


def eq24_sigma_m(rx, i_pk):
    slope = echo.echo_features(
        SHAPE, np.zeros((1, 1)), np.ones((1, 1)), DT, T_D, K_ATT
    ).cfd_slope_per_s[0]
    s25 = timing.sigma_cfd_m(rx.snr(i_pk), slope, K_ATT, T_D, SHAPE.sigma_h_s)
    return timing.range_sigma_m(s25, timing.sigma_quantisation_m(T_T))


def sigma_panel(ax, quick):
    snrs = np.array([4.0, 5.0, 7.0, 10.0, 15.0, 20.0, 30.0, 50.0, 100.0])
    n_each = 1000 if quick else 4000
    out = {}
    for name, rx in (("default", RX), ("thermal", RX_THERMAL)):
        rng = np.random.default_rng(2026)
        arrivals, weights, i_pk = single_surface(snrs, n_each, rng, rx)
        noisy = gate(rng, arrivals, weights, rx, 3.0, 10.0)
        clean = gate(rng, arrivals, weights, rx, 3.0, 10.0, noise=False, resolution_s=0.0)
        err = (noisy.range_m - clean.range_m).reshape(len(snrs), n_each)
        sig = np.array([robust_sigma(e) for e in err])
        i_pk = i_pk.reshape(len(snrs), n_each)[:, 0]
        out[name] = (sig[:, 0], sig[:, 1], i_pk)
    snr_fine = np.geomspace(3.0, 150.0, 60)
    i_fine = i_pk_for_snr(snr_fine, RX)
    eq24 = np.array([eq24_sigma_m(RX, i) for i in i_fine])
    sigma_t = timing.sigma_quantisation_m(T_T)
    aware = np.array(
        [
            np.hypot(montecarlo.cfd_sigma_shot_aware_m(SHAPE, RX, i, T_D, K_ATT), sigma_t)
            for i in i_fine
        ]
    )
    ax.loglog(
        snr_fine,
        1e3 * eq24,
        "--",
        lw=1.5,
        color="C0",
        label="Eq. 24, equal-noise Eq. 25 (paper form eq25_equal_noise)",
    )
    ax.loglog(
        snr_fine,
        1e3 * aware,
        lw=1.8,
        color="C3",
        label="Eq. 24, per-sample Eq. 25 (ours, the default; default rx)",
    )
    ax.axhline(1e3 * sigma_t, color="0.5", lw=0.8, ls=":", label="Eq. 26 sigma_t (100 ps)")
    for name, color, label in (
        ("default", "C3", "MC, default receiver (shot noise)"),
        ("thermal", "C0", "MC, thermal-limited receiver"),
    ):
        sig, n, _ = out[name]
        ax.errorbar(
            snrs,
            1e3 * sig,
            yerr=2e3 * 1.1664 * sig / np.sqrt(n),
            fmt="o" if name == "default" else "s",
            mfc="none" if name == "thermal" else color,
            ms=5,
            color=color,
            capsize=2,
            label=label,
        )
    ax.set_xlabel("SNR_na (Eq. 18)  [1]")
    ax.set_ylabel("range sigma (robust, 1.4826 MAD)  [mm]")
    ax.set_title(f"Range noise at TNR 3, {n_each} pixels per point")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="upper right")
    ratios = {}
    for name, rx in (("default", RX), ("thermal", RX_THERMAL)):
        sig, n, i_pk = out[name]
        ratios[name] = sig / np.array([eq24_sigma_m(rx, i) for i in i_pk])
    aware_pts = np.array(
        [
            np.hypot(montecarlo.cfd_sigma_shot_aware_m(SHAPE, RX, i, T_D, K_ATT), sigma_t)
            for i in out["default"][2]
        ]
    )
    ratios["default_vs_shot_aware"] = out["default"][0] / aware_pts
    return snrs, ratios


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="docs/img/mc_agreement.png")
    parser.add_argument("--quick", action="store_true", help="fewer trials (a draft)")
    args = parser.parse_args()
    t0 = time.perf_counter()
    fig, axes = plt.subplots(1, 2, figsize=(12.5, 5.6))
    worst = pd_panel(axes[0], args.quick)
    snrs, ratios = sigma_panel(axes[1], args.quick)
    fig.suptitle(
        "Statistical model (lines) vs waveform Monte Carlo (points): 5 ns pulse, B = 120 MHz, "
        "dt = 0.42 ns, CFD k = 0.5, t_d = 2.24 ns, T_t = 100 ps",
        fontsize=11,
    )
    fig.tight_layout()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)

    snr, tnr, p_mc, p_27 = worst[1]
    print(
        f"P_d: max |MC - Eq. 27| = {worst[0]:.3f} at SNR {snr:g}, TNR {tnr:g} "
        f"(MC {p_mc:.3f}, Eq. 27 {p_27:.3f})"
    )
    print("range sigma, SNR: MC/Eq.24 (default), MC/shot-aware (default), MC/Eq.24 (thermal)")
    for k, s in enumerate(snrs):
        print(
            f"  {s:5.0f}: {ratios['default'][k]:.3f}  "
            f"{ratios['default_vs_shot_aware'][k]:.3f}  {ratios['thermal'][k]:.3f}"
        )
    print(f"wrote {out} in {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
