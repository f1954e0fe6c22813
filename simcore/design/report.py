"""What a study writes: every trial at every envelope point (Parquet), the feasible front (CSV),
the winning design as scenes (TOML), figures (PNG) and a report in words (Markdown).

Over 500 lines: each output of a study beside the others, in the order the report reads them,
so that a figure's axes and the report's words about it stay one reading apart.
"""

from __future__ import annotations

import csv
import io as _io
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .. import io
from ..scene import dump_scene
from .search import Record
from .study import Study

TRIALS_NAME = "trials.parquet"
FRONT_NAME = "front.csv"
BEST_NAME = "best.toml"
BEST_DIR = "best"
REPORT_NAME = "report.md"
FIGURES = ("front.png", "margins.png", "effects.png")


def _fmt(x: float) -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.4g}"


def trials_table(study: Study, records: Sequence[Record]):
    """One row per record and envelope point: stage, design, envelope keys, every figure."""
    import pyarrow as pa  # noqa: PLC0415

    rows = []
    for rec in records:
        points = rec.points or [{"error": rec.error}]
        for p, figures in enumerate(points):
            row: dict[str, Any] = {
                "record": rec.number,
                "stage": rec.stage,
                "of": rec.of,
                "preset": rec.preset,
                "point": p,
                "feasible": rec.feasible,
                "error": figures.get("error"),
            }
            row |= {f"var.{k}": v for k, v in rec.params.items()}
            env = study.envelope[p] if p < len(study.envelope) else {}
            row |= {f"env.{k}": v for k, v in env.items()}
            row |= {
                f"objective.{n}": v for n, v in zip(study.minimize, rec.objectives, strict=True)
            }
            row |= {k: v for k, v in figures.items() if k != "error"}
            rows.append(row)
    names: dict[str, None] = {}
    for row in rows:
        names.update(dict.fromkeys(row))
    columns = {}
    for name in names:
        values = [row.get(name) for row in rows]
        kinds = {type(v) for v in values if v is not None}
        if kinds <= {int, float} and kinds:
            values = [float(v) if v is not None else None for v in values]
        elif kinds and not kinds <= {bool}:
            values = [None if v is None else str(v) for v in values]
        columns[name] = pa.array(values)
    return pa.table(columns)


def front_rows(study: Study, front: Sequence[Record], confirmed: Sequence[Record]):
    """The front as CSV rows: the design, its costs, each requirement's value and margin, and
    its confirmation (feasible at the confirmation preset, or empty if not confirmed)."""
    by_of = {r.of: r for r in confirmed}
    rows = []
    for rec in front:
        row: dict[str, Any] = {"record": rec.number, "stage": rec.stage}
        row |= dict(rec.params)
        row |= dict(zip(study.minimize, rec.objectives, strict=True))
        for req, value, margin in zip(study.requirements, rec.values, rec.margins, strict=True):
            row[req.text()] = value
            row[f"margin: {req.text()}"] = margin
        conf = by_of.get(rec.number)
        row["confirmed_feasible"] = "" if conf is None else conf.feasible
        rows.append(row)
    return rows


def write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    names: dict[str, None] = {}
    for row in rows:
        names.update(dict.fromkeys(row))
    buf = _io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(names) or ["record"])
    writer.writeheader()
    writer.writerows(rows)
    with io.atomic_path(path) as tmp:
        Path(tmp).write_text(buf.getvalue())


def worst_point(study: Study, rec: Record, i: int) -> int:
    """The envelope point where requirement ``i`` is met least."""
    req = study.requirements[i]
    best, where = math.inf, 0
    for p, figures in enumerate(rec.points):
        value = figures.get(req.figure, math.nan) if "error" not in figures else math.nan
        m = req.margin(value)
        if m < best:
            best, where = m, p
    return where


def binding_point(study: Study, rec: Record, i: int) -> int:
    """The envelope point that decides requirement ``i``: where it is met least for a
    requirement over the worst point; for one at the median, mean or a percentile the point
    whose value is nearest that aggregate (the median is met there, not at the worst point)."""
    req = study.requirements[i]
    if req.over == "worst":
        return worst_point(study, rec, i)
    values = [
        figures.get(req.figure, math.nan) if "error" not in figures else math.nan
        for figures in rec.points
    ]
    target = req.aggregate(values)
    if not math.isfinite(target):
        return worst_point(study, rec, i)
    gaps = [abs(v - target) if math.isfinite(v) else math.inf for v in values]
    return min(range(len(values)), key=lambda p: (gaps[p], req.margin(values[p])))


def binding_requirement(study: Study, rec: Record) -> int:
    """The requirement met by the least share of its bound (the first if none)."""
    if not rec.margins:
        return 0
    rel = [
        m / max(abs(r.bound), 1e-12) for r, m in zip(study.requirements, rec.margins, strict=True)
    ]
    return min(range(len(rel)), key=lambda i: rel[i])


def design_number(rec: Record) -> int:
    """The design's record number as ``front.csv`` and ``trials.parquet`` list it: a
    confirmation's is the screened record it confirms."""
    return rec.of if rec.stage == "confirm" and rec.of >= 0 else rec.number


def write_best(study: Study, rec: Record, out: Path) -> list[Path]:
    """The design as a scene at each envelope point (``best/point_NN.toml``) and, as
    ``best.toml``, at the point that decides its binding requirement (:func:`binding_point`)."""
    written = []
    folder = out / BEST_DIR
    folder.mkdir(parents=True, exist_ok=True)
    for p in range(len(study.envelope)):
        path = folder / f"point_{p:02d}.toml"
        text = dump_scene(study.scene(rec.params, p, rec.preset))
        with io.atomic_path(path) as tmp:
            Path(tmp).write_text(text)
        written.append(path)
    binding = binding_requirement(study, rec)
    point = binding_point(study, rec, binding) if rec.margins else 0
    why = f", where {study.requirements[binding].text()} binds" if rec.margins else ""
    with io.atomic_path(out / BEST_NAME) as tmp:
        Path(tmp).write_text(
            f"# {study.name}: the winning design at envelope point {point} "
            f"({study.envelope[point]}){why}\n"
            + dump_scene(study.scene(rec.params, point, rec.preset))
        )
    return [out / BEST_NAME, *written]


def write_figures(study: Study, records: Sequence[Record], front, winner, out: Path) -> list[Path]:
    """front.png (the costs of every screened design, the front marked), margins.png (the
    winner's margin for each requirement at each envelope point), effects.png (each variable
    against the first cost, feasible designs filled)."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    screened = [r for r in records if r.stage in ("screen", "polish")]
    ok = [r for r in screened if r.feasible]
    bad = [r for r in screened if not r.feasible and all(math.isfinite(x) for x in r.objectives)]
    figures = {  # drawn, written and closed one at a time
        "front.png": lambda: _front_figure(plt, study, screened, ok, bad, front, winner),
        "margins.png": lambda: _margins_figure(plt, study, winner),
        "effects.png": lambda: _effects_figure(plt, study, ok, bad),
    }
    paths = []
    for name, draw in figures.items():
        fig = draw()
        paths.append(_save(fig, out / name))
        plt.close(fig)
    return paths


def _front_figure(plt, study: Study, screened, ok, bad, front, winner):
    """The costs of every screened design (two costs: against each other, the front joined; one:
    against the order run, the winner's level marked)."""
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    if len(study.minimize) >= 2:
        x, y = study.minimize[0], study.minimize[1]
        ax.scatter(
            [r.objectives[0] for r in bad],
            [r.objectives[1] for r in bad],
            s=12,
            c="0.7",
            label="fails a requirement",
        )
        ax.scatter(
            [r.objectives[0] for r in ok],
            [r.objectives[1] for r in ok],
            s=16,
            c="tab:blue",
            label="feasible",
        )
        f = sorted(front, key=lambda r: r.objectives[0])
        ax.plot(
            [r.objectives[0] for r in f],
            [r.objectives[1] for r in f],
            "o-",
            c="tab:red",
            label="front",
        )
        ax.set_xlabel(x)
        ax.set_ylabel(y)
    else:
        x = study.minimize[0]
        ax.scatter(
            [r.number for r in bad],
            [r.objectives[0] for r in bad],
            s=12,
            c="0.7",
            label="fails a requirement",
        )
        ax.scatter(
            [r.number for r in ok],
            [r.objectives[0] for r in ok],
            s=16,
            c="tab:blue",
            label="feasible",
        )
        if winner is not None:
            ax.axhline(
                winner.objectives[0], c="tab:red", lw=1, label=f"winner {winner.objectives[0]:.4g}"
            )
        ax.set_xlabel("design (order run)")
        ax.set_ylabel(x)
    two = len(study.minimize) >= 2
    for k, set_scale in enumerate((ax.set_xscale, ax.set_yscale) if two else (ax.set_yscale,)):
        if _log_axis(study, [r.objectives[k] for r in screened], study.minimize[k]):
            set_scale("log")
    ax.set_title(f"{study.name}: {len(screened)} designs screened ({study.preset})")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _log_axis(study: Study, values, name: str) -> bool:
    """A cost is drawn on a log axis where it is a log variable, or positive and spread over
    more than a decade (designs below 10 mJ piled on 0 on a linear axis)."""
    v = [x for x in values if isinstance(x, (int, float)) and math.isfinite(x)]
    if not v or min(v) <= 0:
        return False
    if any(var.log and var.key == name for var in study.variables):
        return True
    return max(v) / min(v) > 10.0


def _margins_figure(plt, study: Study, winner):
    """The winner's margin over each requirement's bound, one bar per envelope point."""
    fig, ax = plt.subplots(figsize=(6.4, 0.6 + 0.5 * max(1, len(study.requirements))))
    if winner is not None and study.requirements:
        n_points = len(study.envelope)
        for i, req in enumerate(study.requirements):
            margins = []
            for figures in winner.points:
                value = figures.get(req.figure, math.nan) if "error" not in figures else math.nan
                margins.append(req.margin(value) / max(abs(req.bound), 1e-12))
            met = winner.margins[i] >= 0 if i < len(winner.margins) else False
            ys = [i + (p - (n_points - 1) / 2) * 0.6 / max(n_points, 1) for p in range(n_points)]
            # the requirement's colour (met over the envelope as it says: green); a point that
            # fails on its own inside a met "at median" requirement is hatched
            bars = ax.barh(
                ys,
                [m if math.isfinite(m) else -1.0 for m in margins],
                height=0.6 / max(n_points, 1),
                color="tab:green" if met else "tab:red",
                hatch=None,
            )
            for p, (bar, m) in enumerate(zip(bars, margins, strict=True)):
                if met and m < 0:
                    bar.set_hatch("//")
                    bar.set_alpha(0.6)
                ax.annotate(
                    f"p{p}",
                    (bar.get_width(), bar.get_y() + bar.get_height() / 2),
                    xytext=(2 if bar.get_width() >= 0 else -2, 0),
                    textcoords="offset points",
                    ha="left" if bar.get_width() >= 0 else "right",
                    va="center",
                    fontsize=6,
                )
        ax.axvline(0, c="k", lw=0.8)
        ax.set_xscale("symlog", linthresh=0.05)  # a loose requirement does not flatten the rest
        ax.set_yticks(
            range(len(study.requirements)), [r.text() for r in study.requirements], fontsize=8
        )
        ax.set_xlabel(
            "margin over the bound, relative (bar pN: envelope point N; green: requirement met, "
            "hatched: this point fails it)",
            fontsize=8,
        )
        ax.set_title("The winning design's margins")
    else:
        ax.text(0.5, 0.5, "no feasible design", ha="center", va="center")
    fig.tight_layout()
    return fig


def _effects_figure(plt, study: Study, ok, bad):
    """Each variable against the first cost, feasible designs in blue."""
    n = len(study.variables)
    fig, axes = plt.subplots(1, n, figsize=(3.2 * n, 3.0), squeeze=False)
    for ax, var in zip(axes[0], study.variables, strict=True):
        # the cost against itself says nothing: that variable is drawn against the design's
        # least relative margin (its binding requirement's) instead
        itself = var.key == study.minimize[0]

        def ys(group, itself=itself):
            if not itself:
                return [r.objectives[0] for r in group]
            return [_least_margin(study, r) for r in group]

        for group, style in ((bad, {"c": "0.7", "s": 10}), (ok, {"c": "tab:blue", "s": 14})):
            xs = [r.params.get(var.key) for r in group]
            if xs and all(isinstance(v, (int, float)) for v in xs):
                ax.scatter(xs, ys(group), **style)
            elif xs:
                ax.scatter([str(v) for v in xs], ys(group), **style)
        if var.log:
            ax.set_xscale("log")
        ax.set_xlabel(var.key, fontsize=8)
        ax.set_ylabel("least relative margin" if itself else study.minimize[0], fontsize=8)
    fig.suptitle("Each variable against the first cost (blue: feasible)", fontsize=9)
    fig.tight_layout()
    return fig


def _least_margin(study: Study, rec: Record) -> float:
    """The design's smallest margin relative to its requirement's bound (NaN: none)."""
    rel = [
        m / max(abs(r.bound), 1e-12)
        for r, m in zip(study.requirements, rec.margins, strict=True)
        if math.isfinite(m)
    ]
    return min(rel) if rel else math.nan


def _save(fig, path: Path) -> Path:
    with io.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    return path


def report_text(study, records, front, winner, confirmed, tally, wall_s: float) -> str:
    """The study's outcome in words: the winner and by how much each requirement is met at its
    worst envelope point, the binding requirement; or, if no design is feasible, which
    requirement fails at the best trial and by how much."""
    screened = [r for r in records if r.stage == "screen"]
    lines = [
        f"# Design study: {study.name}",
        "",
        f"{len(screened)} designs screened at the {study.preset} preset over "
        f"{len(study.envelope)} envelope points, {sum(r.feasible for r in screened)} feasible; "
        f"{len([r for r in records if r.stage == 'polish'])} polish evaluations; "
        f"{len(confirmed)} confirmed at the {study.confirm_preset} preset; "
        f"wall time {wall_s:.0f} s.",
        "",
        "Requirements: " + "; ".join(r.text() for r in study.requirements) + ".",
        "Minimised: " + ", ".join(study.minimize) + ".",
        "",
    ]
    if study.tracks:
        n = len(study.tracks)
        lines[-1:-1] = [
            f"Tracked: the envelope points are the {len(study.envelope)} frames of {n} "
            f"{'trajectory' if n == 1 else 'trajectories'}, each tracked in time order "
            "(`simcore.tracking.track`); a lost frame's `track.*` errors count as infinite.",
        ]
    if winner is None and confirmed:
        lines += [
            "## No design is confirmed",
            "",
            f"{sum(r.feasible for r in records if r.stage != 'confirm')} designs met every "
            f"requirement at the {study.preset} preset; none of the {len(confirmed)} confirmed "
            f"at the {study.confirm_preset} preset did:",
        ]
        for c in confirmed:
            fails = "; ".join(
                f"{r.text()} at {_fmt(v)} ({_fmt(-m)} short)"
                for r, v, m in zip(study.requirements, c.values, c.margins, strict=True)
                if m < 0
            )
            lines.append(f"- design {c.of} ({_params(c)}): {fails or c.error}")
        lines.append("")
        return "\n".join(lines)
    if winner is None:
        worst = min(
            (r for r in records if r.stage != "confirm"),
            key=lambda r: (r.error is not None, r.violation, r.number),
            default=None,
        )
        lines += ["## No design meets every requirement", ""]
        if worst is not None:
            lines.append(f"Closest: design {worst.number} ({_params(worst)}).")
            for i, (req, value, margin) in enumerate(
                zip(study.requirements, worst.values, worst.margins, strict=True)
            ):
                if margin < 0:
                    p = worst_point(study, worst, i)
                    lines.append(
                        f"- **{req.text()}** fails: {_fmt(value)} ({_fmt(-margin)} short), worst "
                        f"at envelope point {p} ({study.envelope[p]})."
                    )
            if worst.error:
                lines.append(f"- its evaluation failed: {worst.error}")
        lines += _why_infeasible(study, [r for r in records if r.stage != "confirm"])
        lines.append("")
        return "\n".join(lines)
    cost = ", ".join(
        f"{n} = {_fmt(v)}" for n, v in zip(study.minimize, winner.objectives, strict=True)
    )
    lines += [
        "## The winner",
        "",
        f"Design {design_number(winner)} (record {design_number(winner)} of `front.csv`"
        + (f", confirmed as record {winner.number}" if winner.stage == "confirm" else "")
        + f"; {winner.stage}, {winner.preset} preset): {_params(winner)}.",
        f"Cost: {cost}.",
        "",
        "| requirement | value over the envelope | margin | worst envelope point |",
        "|---|---|---|---|",
    ]
    for i, (req, value, margin) in enumerate(
        zip(study.requirements, winner.values, winner.margins, strict=True)
    ):
        p = worst_point(study, winner, i)
        lines.append(
            f"| {req.text()} | {_fmt(value)} | {_fmt(margin)} | {p}: {study.envelope[p]} |"
        )
    if study.requirements:
        rel = [
            m / max(abs(r.bound), 1e-12)
            for r, m in zip(study.requirements, winner.margins, strict=True)
        ]
        binding = min(range(len(rel)), key=lambda i: rel[i])
        point = binding_point(study, winner, binding)
        lines += [
            "",
            f"The binding requirement is **{study.requirements[binding].text()}** "
            f"(met by {100 * rel[binding]:.1f} % of its bound), decided at envelope point "
            f"{point} ({study.envelope[point]}): `best.toml` is the design there.",
        ]
    if len(front) > 1:
        lines += ["", f"The feasible front holds {len(front)} designs (`front.csv`, `front.png`)."]
    if confirmed:
        lines += ["", "## Confirmation at the reference preset", ""]
        for c in confirmed:
            state = (
                "meets every requirement"
                if c.feasible
                else "FAILS: "
                + "; ".join(
                    f"{r.text()} at {_fmt(v)}"
                    for r, v, m in zip(study.requirements, c.values, c.margins, strict=True)
                    if m < 0
                )
            )
            lines.append(
                f"- design {c.of} at {c.preset}: {state}" + (f" ({c.error})" if c.error else "")
            )
    lines += ["", "## The staged cache", "", tally.line() + ".", ""]
    return "\n".join(lines)


def _why_infeasible(study: Study, records: Sequence[Record]) -> list[str]:
    """The binding requirement of a study no design meets (the one whose best value over every
    design falls short by the largest share of its bound), that best value, and its cause: the
    designs' evaluations failing (memory, a refused scene), the figure not moving with the
    variables (a cap of the scene: for recall, the seen surface at the pixel footprint), or the
    variables' ranges ending before it is met."""
    if not study.requirements or not records:
        return []
    failed = [r for r in records if r.error]
    if len(failed) == len(records):
        return ["", f"**Cause**: every design's evaluation failed; the first: {failed[0].error}"]
    best = []
    for i, req in enumerate(study.requirements):
        done = [(r.margins[i], r.values[i], r) for r in records if not r.error and r.margins]
        done = [d for d in done if math.isfinite(d[1])]
        if not done:
            continue
        margin, value, rec = max(done, key=lambda d: (d[0], -d[2].number))
        values = [d[1] for d in done]
        best.append((margin / max(abs(req.bound), 1e-12), i, value, rec, values))
    short = [b for b in best if b[0] < 0]
    if not short:
        return []
    rel, i, value, rec, values = min(short, key=lambda b: b[0])
    req = study.requirements[i]
    spread = max(values) - min(values)
    if spread <= 0.02 * max(abs(req.bound), 1e-12):
        cause = (
            f"it hardly moves with the design variables ({_fmt(min(values))}-"
            f"{_fmt(max(values))} over {len(values)} designs): the scene caps it, not the "
            "design (for recall: the surface seen at the pixel footprint and incidence)"
        )
    else:
        cause = (
            f"it moves with the design ({_fmt(min(values))}-{_fmt(max(values))} over "
            f"{len(values)} designs) but not far enough within the variables' ranges: widen "
            "them or relax the bound"
        )
    lines = [
        "",
        f"**Binding requirement**: {req.text()}; the best any design reached is {_fmt(value)} "
        f"(design {rec.number}, {_fmt(-rel * 100)} % of the bound short). **Cause**: {cause}.",
    ]
    if failed:
        lines.append(f"{len(failed)} designs' evaluations failed; the first: {failed[0].error}")
    return lines


def _params(rec: Record) -> str:
    return ", ".join(
        f"{k} = {_fmt(v) if isinstance(v, float) else v}" for k, v in rec.params.items()
    )
