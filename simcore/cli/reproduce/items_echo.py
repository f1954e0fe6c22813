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
    """Figure 9: P_d and false alarms against TNR, the statistical model's curves (ours and the
    paper's) with the waveform Monte Carlo's points."""
    scene = run.scene()
    rx = receiver.receiver_model(scene.detector, scene.amplifiers, scene.laser.wavelength_m)
    b_hz = scene.detector.bandwidth_hz
    pd = _detection_probability(run, scene, rx)
    fa = _false_alarms(run, scene, rx)
    fig = new_figure(12.0, 4.8)
    ax_pd, ax_fa = fig.subplots(1, 2)
    _draw_detection_probability(ax_pd, pd)
    _draw_false_alarms(ax_fa, fa)
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
            "snr": pd["snr"].tolist(),
            "peak_current_a": pd["i_pk"].tolist(),
            "tnr_curve": pd["tnr_curve"].tolist(),
            "eq27_ours": pd["ours"].tolist(),
            "eq27_paper": pd["paper"].tolist(),
            "tnr_mc": pd["tnr_mc"].tolist(),
            "montecarlo": pd["mc"].tolist(),
            "montecarlo_trials": pd["trials"],
            "eq27_ours_at_mc": pd["ours_at_mc"].tolist(),
            "max_abs_mc_minus_eq27_ours": float(np.abs(pd["mc"] - pd["ours_at_mc"]).max()),
        },
        "false_alarms": {
            "tnr_curve": fa["tnr_curve"].tolist(),
            "eq28_ours_rice": fa["rice"].tolist(),
            "eq28_paper_df12mhz": fa["paper_12"].tolist(),
            "eq28_paper_df_bandwidth": fa["paper_b"].tolist(),
            "tnr_mc": fa["tnr_mc"].tolist(),
            "montecarlo_count": fa["counts"].astype(int).tolist(),
            "montecarlo_pixels": fa["pixels"].astype(int).tolist(),
            "montecarlo_per_pixel": fa["mc"].tolist(),
            "mc_over_rice": (fa["mc"] / fa["rice_at_mc"]).tolist(),
            "mc_over_paper_df12mhz": (fa["mc"] / fa["paper_12_at_mc"]).tolist(),
            "mc_over_paper_df_bandwidth": (fa["mc"] / fa["paper_b_at_mc"]).tolist(),
        },
    }


def _gate(scene, rx, rng, arrivals, weights, n_total: int, tnr: float, gate_m: float):
    """The waveform Monte Carlo of ``n_total`` pixels (the echoes of the first ones given by
    ``arrivals`` and ``weights``) through the arming threshold and the CFD discriminator."""
    from ...receivers.lm_apd import montecarlo  # noqa: PLC0415  (only for this item)

    return montecarlo.scene_gate(
        rng, scene, rx, arrivals, weights, tnr=tnr, gate_m=gate_m, n_pixels_total=n_total
    )


def _detection_probability(run: ReproduceRun, scene, rx) -> dict[str, Any]:
    """P_d of single-surface pixels of known SNR: the Monte Carlo through the discriminator over
    a short gate (10 m) at the settings' TNRs, and Eq. 27 (ours and the paper's) as curves."""
    s = run.settings
    shape = echo.pulse_shape(scene.laser.pulse_width_s, echo.A_FWHM, scene.detector.bandwidth_hz)
    distance = scene.pose.distance_m
    snrs = np.array(FIG9_SNRS)
    i_pk = rx.peak_current_for_snr(snrs)
    n_each = s.mc_pd_trials
    tnr_mc = mc_tnr_grid(s)
    pd_mc = np.zeros((len(snrs), len(tnr_mc)))
    energy = scene.laser.pulse_energy_j
    weights = np.repeat(i_pk / (rx.responsivity_a_w * energy * shape.peak_w_per_j), n_each)
    for j, tnr in enumerate(tnr_mc):
        rng = run.rng(2, j)
        arrivals = 2.0 * rng.uniform(distance - 2.0, distance + 2.0, size=(len(weights), 1)) / C
        res = _gate(scene, rx, rng, arrivals, weights[:, None], len(weights), float(tnr), 10.0)
        pd_mc[:, j] = res.detected.reshape(len(snrs), n_each).mean(axis=1)
        run.step(f"P_d Monte Carlo, TNR {tnr:g}")
    tnr_curve = np.linspace(0.0, 14.0, 281)

    def ours(tnr: np.ndarray) -> np.ndarray:
        return np.array(
            [
                detection.detection_probability(i, tnr * rx.sigma_n_a, rx.sigma_peak_a(i))
                for i in i_pk
            ]
        )

    return {
        "snr": snrs,
        "i_pk": i_pk,
        "trials": n_each,
        "tnr_mc": tnr_mc,
        "mc": pd_mc,
        "tnr_curve": tnr_curve,
        "ours": ours(tnr_curve),
        "paper": np.array([detection.detection_probability_paper(v, tnr_curve) for v in snrs]),
        "ours_at_mc": ours(tnr_mc),
    }


def _false_alarms(run: ReproduceRun, scene, rx) -> dict[str, Any]:
    """False alarms of noise-only pixels over the whole 1 km gate: the Monte Carlo's counts at
    the settings' TNRs (enough pixels for the target count), and Eq. 28 (Rice, ours; the paper's
    with df = 12 MHz and with df = B) as curves and at the Monte Carlo's TNRs."""
    s = run.settings
    b_hz = scene.detector.bandwidth_hz
    fa_tnr = np.array(s.mc_fa_tnrs)
    counts: list[int] = []
    pixels: list[int] = []
    for j, tnr in enumerate(fa_tnr):
        per_pixel = detection.false_alarms_per_pixel(tnr, FIG9_GATE_M, b_hz)
        n_px = int(min(s.mc_fa_max_pixels, math.ceil(s.mc_fa_target_count / per_pixel)))
        empty = np.zeros((0, 1))
        res = _gate(scene, rx, run.rng(3, j), empty, empty, n_px, float(tnr), FIG9_GATE_M)
        counts.append(res.n_false_alarms)
        pixels.append(n_px)
        run.step(f"false-alarm Monte Carlo, TNR {tnr:g}")
    fa_counts = np.array(counts, dtype=np.float64)
    fa_pixels = np.array(pixels, dtype=np.float64)
    fa_curve_tnr = np.linspace(1.0, 8.0, 141)

    def rice(tnr: np.ndarray) -> np.ndarray:
        return detection.false_alarms_per_pixel(tnr, FIG9_GATE_M, b_hz)

    def paper(tnr: np.ndarray, df_hz: float) -> np.ndarray:
        return detection.false_alarms_per_pixel_paper(tnr, FIG9_GATE_M, df_hz)

    return {
        "tnr_mc": fa_tnr,
        "counts": fa_counts,
        "pixels": fa_pixels,
        "mc": fa_counts / fa_pixels,
        "tnr_curve": fa_curve_tnr,
        "rice": rice(fa_curve_tnr),
        "paper_12": paper(fa_curve_tnr, FIG9_DF_HZ),
        "paper_b": paper(fa_curve_tnr, b_hz),
        "rice_at_mc": rice(fa_tnr),
        "paper_12_at_mc": paper(fa_tnr, FIG9_DF_HZ),
        "paper_b_at_mc": paper(fa_tnr, b_hz),
    }


def _draw_detection_probability(ax, pd: dict[str, Any]) -> None:
    """Eq. 27 (ours solid, the paper's dashed) per SNR, the Monte Carlo with 2 binomial sigma."""
    n_each = pd["trials"]
    for k, snr in enumerate(pd["snr"]):
        color = f"C{k}"
        ax.plot(
            pd["tnr_curve"], pd["ours"][k], color=color, lw=1.6, label=f"SNR {snr:g}: Eq. 27 ours"
        )
        ax.plot(pd["tnr_curve"], pd["paper"][k], color=color, lw=1.2, ls="--")
        mc = pd["mc"][k]
        err = np.sqrt(np.maximum(mc * (1 - mc), 1.0 / n_each) / n_each)
        ax.errorbar(pd["tnr_mc"], mc, yerr=2 * err, fmt="o", ms=3.5, color=color, capsize=2)
    ax.plot([], [], "k--", lw=1.2, label="Eq. 27 paper (thermal only)")
    ax.plot([], [], "ko", ms=3.5, label=f"waveform Monte Carlo ({n_each} pixels, 2 sigma)")
    ax.set_xlabel("TNR = V_T / sigma_n  [1]")
    ax.set_ylabel("detection probability P_d  [1]")
    ax.set_xlim(0, 14)
    ax.set_ylim(-0.03, 1.03)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7.5, loc="upper left", bbox_to_anchor=(0.0, -0.13), ncol=3)
    ax.set_title("Detection probability of a single surface")


def _draw_false_alarms(ax, fa: dict[str, Any]) -> None:
    """Eq. 28: Rice (ours) and the paper's form with df = 12 MHz and df = B, the Monte Carlo per
    pixel with 2 Poisson sigma. The one drawing of this figure (the Monte Carlo agreement
    script leaves false alarms to it)."""
    tnr = fa["tnr_curve"]
    ax.semilogy(tnr, fa["rice"], lw=1.8, color="C0", label="Eq. 28 ours (Rice, B = 120 MHz)")
    ax.semilogy(
        tnr, fa["paper_12"], ls=":", lw=1.6, color="C3", label="Eq. 28 paper, df = 12 MHz (Fig. 9)"
    )
    ax.semilogy(
        tnr, fa["paper_b"], ls="--", lw=1.4, color="C1", label="Eq. 28 paper, df = B = 120 MHz"
    )
    ax.errorbar(
        fa["tnr_mc"],
        fa["mc"],
        yerr=2.0 * np.sqrt(np.maximum(fa["counts"], 1.0)) / fa["pixels"],
        fmt="o",
        ms=4,
        color="k",
        capsize=2,
        label="waveform Monte Carlo (2 Poisson sigma)",
    )
    ax.set_xlabel("TNR = V_T / sigma_n  [1]")
    ax.set_ylabel("false alarms per pixel per pulse  [1]")
    ax.set_title(f"False alarms in a {FIG9_GATE_M / 1e3:g} km range gate")
    ax.set_ylim(1e-6, 1e3)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7.5, loc="upper right")


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
