"""MkDocs hook: the pages' generated parts, made from the code at build time (never hand-copied).

A page asks for one with a marker on a line of its own:

``<!-- generated: scene-keys -->``
    every scene key with its unit, default, valid range and meaning (``lmapd keys --markdown``,
    from the key registry of ``simcore.scene``);
``<!-- generated: cli -->``
    each ``lmapd`` command's ``--help``, from its argparse parser;
``<!-- generated: bench -->``
    the stage timings of the ``lmapd bench --json`` run committed as ``docs/data/bench.json``,
    with the machine and the date it ran on;
``<!-- generated: atlas-bench -->``
    the atlas's costs from the ``lmapd bench --atlas --json`` run committed as
    ``docs/data/atlas_bench.json``;
``<!-- generated: validation -->``
    the echo stage against Mitsuba 3 with mitransient, from the ``make validate`` run committed
    as ``docs/data/validation.json``.

The same functions serve the tests (``tests/test_docs.py``), which check that every key and every
command appears. Not part of the site (``exclude_docs`` in mkdocs.yml).
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

from simcore.cli import SUBCOMMANDS, build_parser
from simcore.scene import key_reference

DOCS = Path(__file__).resolve().parent.parent
BENCH_JSON = DOCS / "data" / "bench.json"
ATLAS_BENCH_JSON = DOCS / "data" / "atlas_bench.json"
VALIDATION_JSON = DOCS / "data" / "validation.json"
MARKER = re.compile(r"^<!-- generated: ([a-z-]+) -->$", re.MULTILINE)
FRAME_STAGES = ("hits", "echo", "background", "receiver", "detection", "cloud")


def scene_keys_markdown() -> str:
    """The key reference as ``lmapd keys --markdown`` prints it."""
    lines = ["| key | unit | default | valid | meaning |", "|---|---|---|---|---|"]
    for r in key_reference():
        lines.append(f"| `{r['key']}` | {r['unit']} | {r['default']} | {r['valid']} | {r['doc']} |")
    return "\n".join(lines)


def cli_markdown() -> str:
    """``lmapd --help`` and each command's ``--help`` (argparse's own text, 100 columns)."""
    os.environ["COLUMNS"] = "100"  # argparse wraps to the terminal: one width for the page
    parser = build_parser()
    (sub,) = [a for a in parser._actions if a.dest == "command"]  # the subparsers action
    parts = ["## lmapd", "", "```text", parser.format_help().rstrip(), "```"]
    for module in SUBCOMMANDS:
        name = module.__name__.rsplit(".", 1)[-1].replace("_", "-")
        command = sub.choices[name]
        parts += ["", f"## lmapd {name}", "", "```text", command.format_help().rstrip(), "```"]
    return "\n".join(parts)


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.1f}"


def bench_markdown(path: Path = BENCH_JSON) -> str:
    """The committed ``lmapd bench --json`` run as a table, headed by its machine and date."""
    fig = json.loads(path.read_text(encoding="utf-8"))
    machine = fig.get("machine", {})
    head = [
        f"Run on {fig.get('date_utc', 'an unrecorded date')} (UTC), "
        f"{machine.get('cpu', 'an unrecorded CPU')}, {machine.get('cpus', '?')} CPUs, "
        f"Python {machine.get('python', '?')}, {machine.get('platform', '')}; "
        f"{fig['repeats']} frames per configuration, medians"
        + (" (`--quick`: up to 256 x 256)." if fig.get("quick") else "."),
        "",
        f"MRO mesh load {_ms(fig['mesh_load_s'])} ms, BVH build {_ms(fig['bvh_build_s'])} ms "
        "(once per target).",
    ]
    if "load_average" in fig:
        load = fig["load_average"]
        head.append(
            f"1-minute load average {load['before']:.2f} before the run, {load['after']:.2f} after."
        )
    stages = [s for s in FRAME_STAGES if any(s in r["stages_s"] for r in fig["frames"])]
    rows = [
        "",
        "| pixels | sub-rays | frame (ms) | ray cast alone (ms) | "
        + " | ".join(f"{s} (ms)" for s in stages)
        + " |",
        "|---|---|---|---|" + "---|" * len(stages),
    ]
    for r in fig["frames"]:
        cast = _ms(r["ray_cast_s"]["median"]) if "ray_cast_s" in r else "-"
        cells = " | ".join(_ms(r["stages_s"].get(s, 0.0)) for s in stages)
        rows.append(
            f"| {r['pixels']} x {r['pixels']} | {r['subrays']} | {_ms(r['frame_s'])} | {cast} | "
            f"{cells} |"
        )
    rerun, mem = fig["rerun_256_s"], fig["memory_256x256x16_mb"]
    rows += [
        "",
        f"Cached re-run at 256 x 256 x 4: after a TNR change {_ms(rerun['tnr'])} ms, after a "
        f"pulse-energy change {_ms(rerun['pulse_energy'])} ms. Peak memory (RSS) of a 256 x 256 x "
        f"16-sub-ray frame: {mem['peak']:.0f} MB ({mem['after_imports']:.0f} MB after the imports "
        "and the MRO).",
    ]
    if "threads" in fig:  # the frames' threads and the scaling tables
        from simcore.cli.bench.stages import format_scaling  # noqa: PLC0415  (the chain)

        rows += ["", f"Frames on {fig['threads']} threads.", *format_scaling(fig["scaling"])]
    return "\n".join(head + rows)


def _spread_ms(values) -> str:
    v = sorted(values)
    return f"{v[len(v) // 2] * 1e3:.0f} ms ({v[0] * 1e3:.0f}-{v[-1] * 1e3:.0f})"


def atlas_bench_markdown(path: Path = ATLAS_BENCH_JSON) -> str:
    """The committed ``lmapd bench --atlas --json`` run: the quality stage A/B and each atlas."""
    fig = json.loads(path.read_text(encoding="utf-8"))
    machine = fig.get("machine", {})
    q = fig["quality_s"]
    lines = [
        f"Run on {fig.get('date_utc', 'an unrecorded date')} (UTC), {machine.get('cpu', '?')}, "
        f"{machine.get('cpus', '?')} CPUs, 1-minute load average {fig['load_average']:.2f} "
        "before the run; medians with their ranges.",
        "",
        f"The quality stage of one frame at {fig['quality_pixels']} x {fig['quality_pixels']} px "
        f"(12 attitudes x {len(q['shared']) // 12}, interleaved): {_spread_ms(q['shared'])} with "
        "the recall's surface samples and the mesh's closest-point tree shared, "
        f"{_spread_ms(q['anew'])} making both anew for each frame (as every frame did before).",
        "",
        "| pixels | attitudes | workers | wall time (s) | a frame with its quality figures |",
        "|---|---|---|---|---|",
    ]
    for a in fig["atlas"]:
        lines.append(
            f"| {a['pixels']} x {a['pixels']} | {a['n_attitudes']} | {fig['workers']} | "
            f"{a['wall_s']:.1f} | {_spread_ms(a['frame_s'])} |"
        )
    lines += [
        "",
        "The wall time runs from the call to the files written: the cluster's start (about 3 s), "
        "each worker's first frame (the MRO's mesh and BVH), the map and its silhouettes.",
    ]
    return "\n".join(lines)


def _g(value, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}g}"


def _scene_title(name: str, scene: dict) -> str:
    if "incidence_deg" in scene:
        return f"plate, {scene['incidence_deg']:g} deg"
    return name.upper() if name == "mro" else name


def _fidelity_title(name: str, f: dict) -> str:
    rays = f"{f['subrays']} sub-ray" + ("s" if f["subrays"] > 1 else "")
    if f.get("refine_subrays"):
        rays += f", {f['refine_subrays']} at mixed pixels"
    return f"{name} ({rays})"


def validation_markdown(path: Path = VALIDATION_JSON) -> str:
    """The committed ``make validate`` run: per scene and simcore fidelity, lit pixels, energy,
    echo timing and the whole target's echo against Mitsuba 3 with mitransient."""
    fig = json.loads(path.read_text(encoding="utf-8"))
    machine = fig.get("machine", {})
    lines = [
        f"Run on {fig['date_utc']} (UTC), {machine.get('cpu', '?')}, {machine.get('cpus', '?')} "
        f"CPUs, 1-minute load average {fig['load_average_before']:.1f} before the run: Mitsuba "
        f"{fig['mitsuba']} ({fig['variant']}), mitransient {fig['mitransient']}, "
        f"{fig['pixels']} x {fig['pixels']} px at {fig['distance_m']:g} m; "
        f"{fig['steady_samples_per_pixel']} stratified samples per pixel for the energies, "
        f"{fig['transient_spp']} for the echoes; {fig['wall_s'] / 60:.0f} minutes in all. "
        "Differences are absolute, Mitsuba's figure less simcore's; *max* over the interior "
        "pixels, *p95* over all the pixels both light.",
        "",
        "| scene | simcore | lit pixels simcore / Mitsuba (Mitsuba's alone: their energy share) "
        "| energy, relative: max (p95) | mean delay: max (p95) [ps] "
        "| half-max time: max (p95) [ps] "
        "| whole echo rms simcore / Mitsuba / closed form [ps] |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, scene in fig["scenes"].items():
        for fidelity, f in scene["fidelity"].items():
            lit, whole = f["lit"], f["whole_echo"]
            alone = f" ({lit['only_b']}: {_g(lit['only_b_energy_share'])})" if lit["only_b"] else ""
            mean, half = f["mean_delay_ps"], f["t_half_ps"]
            closed = whole.get("closed_form_rms_ps")
            lines.append(
                f"| {_scene_title(name, scene)} | {_fidelity_title(fidelity, f)} "
                f"| {lit['a']} / {lit['b']}{alone} "
                f"| {_g(f['energy_interior']['max'])} ({_g(f['energy_lit_both']['p95'])}) "
                f"| {_g(mean['interior']['max'])} ({_g(mean['lit_both']['p95'])}) "
                f"| {_g(half['interior']['max'])} ({_g(half['lit_both']['p95'])}) "
                f"| {whole['simcore_rms_ps']:.1f} / {whole['mitsuba_rms_ps']:.1f} / "
                f"{'-' if closed is None else f'{closed:.1f}'} |"
            )
    multi = fig.get("multi_bounce_mro")
    if multi:
        parts = [
            f"albedo {albedo}: {100 * (m['depth_3']['energy_ratio'] - 1):+.2f} % with a second "
            f"bounce, {100 * (m['depth_16']['energy_ratio'] - 1):+.2f} % with up to 15"
            for albedo, m in multi.items()
        ]
        lines += [
            "",
            "Light that bounces more than once, the MRO's whole echo energy against the single "
            "bounce (Mitsuba's path tracer): " + "; ".join(parts) + ".",
        ]
    return "\n".join(lines)


GENERATORS = {
    "scene-keys": scene_keys_markdown,
    "cli": cli_markdown,
    "bench": bench_markdown,
    "atlas-bench": atlas_bench_markdown,
    "validation": validation_markdown,
}


def on_page_markdown(markdown: str, page, config, files) -> str:
    """Replace each marker with its generated Markdown (an unknown marker fails the build)."""
    return MARKER.sub(lambda m: GENERATORS[m.group(1)](), markdown)
