"""``lmapd simulate``: one flash of the imaging chain, its point cloud and JSON summary.

lmapd simulate [SCENE.toml] [--set NAME=VALUE ...] --out cloud.ply
               [--summary summary.json] [--waveforms waveforms.npz]
"""

from __future__ import annotations

import argparse
from typing import Any

from .common import add_scene_argument, check_output, say, scene_from_args, staged_outputs


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``simulate`` subcommand on ``subparsers`` (from ``add_subparsers``)."""
    from ..scene import PRESETS  # noqa: PLC0415  (light: no numpy)

    sim = subparsers.add_parser("simulate", help="simulate one flash and write its point cloud")
    add_scene_argument(sim)
    sim.add_argument(
        "--set",
        action="append",
        metavar="NAME=VALUE",
        help="override a scene key (pitch_deg, azimuth_deg, distance_m, pixels, pulse_energy_j, "
        "tnr, seed, or any dotted key such as laser.pulse_width_s); repeatable",
    )
    sim.add_argument(
        "--preset", choices=sorted(PRESETS), help="fidelity preset (sub-rays, time step)"
    )
    sim.add_argument("--out", required=True, help="point cloud file (.ply or .las, by suffix)")
    sim.add_argument("--summary", help="JSON summary file")
    sim.add_argument("--waveforms", help="waveform cube of the lit pixels (.npz or .h5)")
    sim.set_defaults(func=run_cli)
    return sim


def run_cli(args: argparse.Namespace) -> int:
    """Run ``lmapd simulate``; return the exit status (0). User errors raise."""
    from .. import io  # noqa: PLC0415  (numpy and the writers; not at --help time)

    out = check_output(args.out, io.CLOUD_SUFFIXES, "--out")
    summary_path = check_output(args.summary, (".json",), "--summary")
    wave_path = check_output(args.waveforms, io.WAVEFORM_SUFFIXES, "--waveforms")
    scene = scene_from_args(args)
    from ..materials import MATERIAL_NAMES  # noqa: PLC0415  (the imaging chain: input checked)
    from ..pipeline import Pipeline  # noqa: PLC0415

    outputs = {"--out": out, "--waveforms": wave_path, "--summary": summary_path}
    with staged_outputs(outputs) as staged:  # every place writable before any work; all or none
        result = Pipeline().run(scene)
        summary = result.summary()
        summary["material_names"] = list(MATERIAL_NAMES)
        comments = (
            "lmapd-sim point cloud, sensor frame (x right, y down, z boresight), metres",
            f"scene {scene.name}",
            f"target {result.target.name}; {result.target.credit}",
            f"material_id indexes: {' '.join(MATERIAL_NAMES)}",
            f"part_id indexes: {' | '.join(result.target.part_names)}",
            "ground truth: true_range_m, range_error_m (measured - true) [m], incidence_deg "
            f"[deg], outlier (a false alarm or more than quality.tau_m = "
            f"{scene.quality.tau_m:g} m off its surface)",
        )
        io.write_cloud(staged["--out"], result.cloud, comments)
        if "--waveforms" in staged:
            io.write_waveforms(staged["--waveforms"], result)
        if "--summary" in staged:
            io.write_json(staged["--summary"], summary)
    total_ms = 1e3 * sum(result.timings_s.values())
    say(
        f"{summary['n_points']} points ({summary['n_outliers']} outliers, "
        f"{summary['n_dropped']} of {summary['n_lit_pixels']} lit pixels dropped) "
        f"-> {out}  [{total_ms:.0f} ms]"
    )
    for line in summary.get("warnings", []):
        say(f"warning: {line}")
    if summary.get("gm.range_bias_m") is not None:
        say(gm_line(summary))
    if scene.sun.mode != "none":
        say(background_line(summary))
    return 0


def background_line(summary: dict) -> str:
    """One line of the summary's background statistics (with a Sun)."""
    if summary["eclipsed"] and not summary["n_earth_pixels"]:
        return "background: the target is in the Earth's shadow, no sunlit Earth in view"
    angle = summary["sun_angle_deg"]
    return (
        f"background: Sun {angle:.1f} deg from the line of sight"
        f"{' (target eclipsed)' if summary['eclipsed'] else ''}, "
        f"median {summary['background_power_w_median']:.3g} W over the lit target pixels, "
        f"max {summary['background_power_w_max']:.3g} W; {summary['n_sunlit_pixels']} sunlit "
        f"target pixels, {summary['n_earth_pixels']} Earth pixels, "
        f"{summary['n_false_expected']:.3g} false points expected"
        + (f", {summary['n_saturated']} saturated" if summary["n_saturated"] else "")
    )


def gm_line(summary: dict) -> str:
    """One line of the Geiger-mode range figures: predicted bias and sd as the histogram
    gives them, and the piled-up share of the lit pixels."""
    sigma = summary.get("gm.range_sigma_m")
    return (
        f"Geiger mode: range bias {1e3 * summary['gm.range_bias_m']:+.1f} mm, sd "
        f"{1e3 * (sigma if sigma is not None else float('nan')):.1f} mm (predicted for the "
        f"histogram's estimator); {100 * summary['gm.saturated_pixel_fraction']:.0f} % of the "
        f"lit pixels piled up (median {summary['gm.signal_pe_median']:.3g} photoelectrons a pulse)"
    )
