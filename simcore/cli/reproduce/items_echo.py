"""The items of ``lmapd reproduce`` about one pixel's echo: the BRDF (Figure 2), detection
probability and false alarms (Figure 9) and single-pixel waveforms (Figure 14)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ... import echo
from ...materials import LIBRARY, MATERIAL_NAMES, material_brdf
from ...receivers.lm_apd import apd as receiver
from ...receivers.lm_apd import detection
from ...reproduce import (
    FIG9_DF_HZ,
    FIG9_GATE_M,
    FIG9_SNRS,
    C,
    find_pixels,
    mc_tnr_grid,
    run_summary,
)
from .draw import credit_line, new_figure, plot_waveform
from .run import ReproduceRun


def item_brdf(run: ReproduceRun) -> dict[str, Any]:
    angle_deg = np.linspace(0.0, 90.0, 361)
    cos_t = np.cos(np.radians(angle_deg))
    names = [n for n in MATERIAL_NAMES if n != "lambertian"] + ["lambertian"]
    rho = {n: material_brdf(cos_t, LIBRARY[n]) for n in names}
    fig = new_figure(11.0, 4.4)
    ax_lin, ax_log = fig.subplots(1, 2)
    for n in names:
        style = {"ls": "--", "color": "0.3"} if n == "lambertian" else {}
        for ax in (ax_lin, ax_log):
            ax.plot(angle_deg, rho[n], lw=1.6, label=LIBRARY[n].label, **style)
    ax_log.set_yscale("log")
    ax_log.set_ylim(1e-6, 3.0)
    for ax in (ax_lin, ax_log):
        ax.set_xlabel("incidence angle theta [deg]")
        ax.set_ylabel("BRDF rho [1/sr]")
        ax.set_xlim(0, 90)
        ax.grid(alpha=0.3, which="both")
    ax_lin.set_title("Eq. 6, linear")
    ax_log.set_title("Eq. 6, logarithmic (specular lobes, grazing fall-off)")
    ax_lin.legend(fontsize=8)
    fig.suptitle("BRDF of the Table 1 materials against incidence angle (paper Figure 2)")
    figure = run.save(fig, "fig02_brdf.png")
    run.step("BRDF")
    return {
        "paper_figure": "Figure 2",
        "figures": [figure],
        "scenes": {},
        "parameters": {
            n: {"A": LIBRARY[n].A, "B": LIBRARY[n].B, "m": LIBRARY[n].m, "s": LIBRARY[n].s}
            for n in names
        },
        "angle_deg": angle_deg.tolist(),
        "brdf_per_sr": {n: rho[n].tolist() for n in names},
    }


def item_detection(run: ReproduceRun) -> dict[str, Any]:
    from ...receivers.lm_apd import montecarlo  # noqa: PLC0415  (only for this item)

    s = run.settings
    scene = run.scene()
    rx = receiver.receiver_model(scene.detector, scene.amplifiers, scene.laser.wavelength_m)
    shape = echo.pulse_shape(scene.laser.pulse_width_s, echo.A_FWHM, scene.detector.bandwidth_hz)
    energy = scene.laser.pulse_energy_j
    b_hz = scene.detector.bandwidth_hz
    distance = scene.pose.distance_m

    def gate(rng, arrivals, weights, n_total, tnr, gate_m):
        return montecarlo.scene_gate(
            rng, scene, rx, arrivals, weights, tnr=tnr, gate_m=gate_m, n_pixels_total=n_total
        )

    # P_d: single-surface pixels of known SNR through the discriminator; a short gate (10 m)
    snrs = np.array(FIG9_SNRS)
    i_pk = rx.peak_current_for_snr(snrs)
    n_each = s.mc_pd_trials
    tnr_mc = mc_tnr_grid(s)
    pd_mc = np.zeros((len(snrs), len(tnr_mc)))
    weights = np.repeat(i_pk / (rx.responsivity_a_w * energy * shape.peak_w_per_j), n_each)
    for j, tnr in enumerate(tnr_mc):
        rng = run.rng(2, j)
        arrivals = 2.0 * rng.uniform(distance - 2.0, distance + 2.0, size=(len(weights), 1)) / C
        res = gate(rng, arrivals, weights[:, None], len(weights), float(tnr), 10.0)
        pd_mc[:, j] = res.detected.reshape(len(snrs), n_each).mean(axis=1)
        run.step(f"P_d Monte Carlo, TNR {tnr:g}")
    tnr_curve = np.linspace(0.0, 14.0, 281)
    pd_ours = np.array(
        [
            detection.detection_probability(i, tnr_curve * rx.sigma_n_a, rx.sigma_peak_a(i))
            for i in i_pk
        ]
    )
    pd_paper = np.array([detection.detection_probability_paper(v, tnr_curve) for v in snrs])
    pd_ours_at_mc = np.array(
        [
            detection.detection_probability(i, tnr_mc * rx.sigma_n_a, rx.sigma_peak_a(i))
            for i in i_pk
        ]
    )

    # false alarms: noise-only pixels over the whole 1 km gate
    fa_tnr = np.array(s.mc_fa_tnrs)
    counts: list[int] = []
    pixels: list[int] = []
    for j, tnr in enumerate(fa_tnr):
        per_pixel = detection.false_alarms_per_pixel(tnr, FIG9_GATE_M, b_hz)
        n_px = int(min(s.mc_fa_max_pixels, math.ceil(s.mc_fa_target_count / per_pixel)))
        empty = np.zeros((0, 1))
        res = gate(run.rng(3, j), empty, empty, n_px, float(tnr), FIG9_GATE_M)
        counts.append(res.n_false_alarms)
        pixels.append(n_px)
        run.step(f"false-alarm Monte Carlo, TNR {tnr:g}")
    fa_counts = np.array(counts, dtype=np.float64)
    fa_pixels = np.array(pixels, dtype=np.float64)
    fa_mc = fa_counts / fa_pixels
    fa_curve_tnr = np.linspace(1.0, 8.0, 141)
    rice = detection.false_alarms_per_pixel(fa_curve_tnr, FIG9_GATE_M, b_hz)
    paper_12 = detection.false_alarms_per_pixel_paper(fa_curve_tnr, FIG9_GATE_M, FIG9_DF_HZ)
    paper_b = detection.false_alarms_per_pixel_paper(fa_curve_tnr, FIG9_GATE_M, b_hz)
    rice_pts = detection.false_alarms_per_pixel(fa_tnr, FIG9_GATE_M, b_hz)
    paper12_pts = detection.false_alarms_per_pixel_paper(fa_tnr, FIG9_GATE_M, FIG9_DF_HZ)
    paperb_pts = detection.false_alarms_per_pixel_paper(fa_tnr, FIG9_GATE_M, b_hz)

    fig = new_figure(12.0, 4.8)
    ax_pd, ax_fa = fig.subplots(1, 2)
    for k, snr in enumerate(snrs):
        color = f"C{k}"
        ax_pd.plot(tnr_curve, pd_ours[k], color=color, lw=1.6, label=f"SNR {snr:g}: Eq. 27 ours")
        ax_pd.plot(tnr_curve, pd_paper[k], color=color, lw=1.2, ls="--")
        err = np.sqrt(np.maximum(pd_mc[k] * (1 - pd_mc[k]), 1.0 / n_each) / n_each)
        ax_pd.errorbar(tnr_mc, pd_mc[k], yerr=2 * err, fmt="o", ms=3.5, color=color, capsize=2)
    ax_pd.plot([], [], "k--", lw=1.2, label="Eq. 27 paper (thermal only)")
    ax_pd.plot([], [], "ko", ms=3.5, label=f"waveform Monte Carlo ({n_each} pixels, 2 sigma)")
    ax_pd.set_xlabel("TNR = V_T / sigma_n  [1]")
    ax_pd.set_ylabel("detection probability P_d  [1]")
    ax_pd.set_xlim(0, 14)
    ax_pd.set_ylim(-0.03, 1.03)
    ax_pd.grid(alpha=0.3)
    ax_pd.legend(fontsize=7.5, loc="upper left", bbox_to_anchor=(0.0, -0.13), ncol=3)
    ax_pd.set_title("Detection probability of a single surface")
    ax_fa.semilogy(fa_curve_tnr, rice, lw=1.8, color="C0", label="Eq. 28 ours (Rice, B = 120 MHz)")
    ax_fa.semilogy(
        fa_curve_tnr,
        paper_12,
        ls=":",
        lw=1.6,
        color="C3",
        label="Eq. 28 paper, df = 12 MHz (Fig. 9)",
    )
    ax_fa.semilogy(
        fa_curve_tnr, paper_b, ls="--", lw=1.4, color="C1", label="Eq. 28 paper, df = B = 120 MHz"
    )
    ax_fa.errorbar(
        fa_tnr,
        fa_mc,
        yerr=2.0 * np.sqrt(np.maximum(fa_counts, 1.0)) / fa_pixels,
        fmt="o",
        ms=4,
        color="k",
        capsize=2,
        label="waveform Monte Carlo (2 Poisson sigma)",
    )
    ax_fa.set_xlabel("TNR = V_T / sigma_n  [1]")
    ax_fa.set_ylabel("false alarms per pixel per pulse  [1]")
    ax_fa.set_title(f"False alarms in a {FIG9_GATE_M / 1e3:g} km range gate")
    ax_fa.set_ylim(1e-6, 1e3)
    ax_fa.grid(alpha=0.3, which="both")
    ax_fa.legend(fontsize=7.5, loc="upper right")
    fig.suptitle(
        "P_d and false alarms against TNR (paper Figure 9): curves = statistical model, points = "
        "noisy waveforms through the CFD discriminator"
    )
    figure = run.save(fig, "fig09_detection.png")
    run.step("Figure 9")
    return {
        "paper_figure": "Figure 9",
        "figures": [figure],
        "scenes": {"receiver": scene.to_dict()},
        "gate_m": FIG9_GATE_M,
        "paper_df_hz": FIG9_DF_HZ,
        "bandwidth_hz": b_hz,
        "sigma_n_a": rx.sigma_n_a,
        "p_detect": {
            "snr": snrs.tolist(),
            "peak_current_a": i_pk.tolist(),
            "tnr_curve": tnr_curve.tolist(),
            "eq27_ours": pd_ours.tolist(),
            "eq27_paper": pd_paper.tolist(),
            "tnr_mc": tnr_mc.tolist(),
            "montecarlo": pd_mc.tolist(),
            "montecarlo_trials": n_each,
            "eq27_ours_at_mc": pd_ours_at_mc.tolist(),
            "max_abs_mc_minus_eq27_ours": float(np.abs(pd_mc - pd_ours_at_mc).max()),
        },
        "false_alarms": {
            "tnr_curve": fa_curve_tnr.tolist(),
            "eq28_ours_rice": rice.tolist(),
            "eq28_paper_df12mhz": paper_12.tolist(),
            "eq28_paper_df_bandwidth": paper_b.tolist(),
            "tnr_mc": fa_tnr.tolist(),
            "montecarlo_count": fa_counts.astype(int).tolist(),
            "montecarlo_pixels": fa_pixels.astype(int).tolist(),
            "montecarlo_per_pixel": fa_mc.tolist(),
            "mc_over_rice": (fa_mc / rice_pts).tolist(),
            "mc_over_paper_df12mhz": (fa_mc / paper12_pts).tolist(),
            "mc_over_paper_df_bandwidth": (fa_mc / paperb_pts).tolist(),
        },
    }


def item_waveforms(run: ReproduceRun) -> dict[str, Any]:
    scene = run.scene({"preset": "reference", "pixels": run.settings.waveform_pixels})
    result = run.run(scene)
    found = find_pixels(result)
    run.step("waveform pixels")
    fig = new_figure(15.0, 4.8)
    ax_img, ax_a, ax_b = fig.subplots(1, 3, width_ratios=(0.8, 1.0, 1.0))
    rng_img = result.range_image_m - scene.pose.distance_m
    im = ax_img.imshow(rng_img, cmap="viridis", interpolation="nearest")
    fig.colorbar(im, ax=ax_img, shrink=0.8, label="range - 500 m [m]")
    ax_img.set_title("range image (front view), the two pixels", fontsize=9)
    ax_img.set_xlabel("column")
    ax_img.set_ylabel("row")
    numbers: dict[str, Any] = {}
    for ax, key, title, marker in (
        (ax_a, "double_peak", "Dish rim over the bus", "o"),
        (ax_b, "dish", "Curved dish, largest single-surface spread", "s"),
    ):
        info = found[key]
        if info is None:
            ax.set_title(f"{title}: no such pixel in this view")
            numbers[key] = None
            continue
        ax_img.plot(
            info["col"], info["row"], marker, mfc="none", mec="red", ms=10, mew=1.6, label=title
        )
        numbers[key] = plot_waveform(ax, result, info, title)
    ax_img.legend(fontsize=7, loc="lower right")
    fig.suptitle(
        "Single-pixel echoes on the MRO at 500 m, 8 x 8 sub-rays per pixel (paper Figure 14)"
    )
    credit_line(fig, result.target.credit)
    figure = run.save(fig, "fig14_waveforms.png")
    run.step("Figure 14")
    return {
        "paper_figure": "Figure 14",
        "figures": [figure],
        "scenes": {"waveforms": scene.to_dict()},
        "summary": run_summary(result),
        "pixels": numbers,
    }
