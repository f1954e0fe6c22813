"""The Design page's payloads: a finished study's costs and front (a plotly figure) and the rows
of its front designs with their requirement margins (simcore.design.open_study's folder)."""

from __future__ import annotations

import math
from typing import Any

from app.payloads.charts import base_layout, note
from simcore.design import StudyFolder
from simcore.design.report import worst_point


def _finite(values) -> bool:
    return all(isinstance(v, (int, float)) and math.isfinite(v) for v in values)


def front_figure(folder: StudyFolder) -> dict[str, Any]:
    """Every screened design's costs (grey: fails a requirement, blue: feasible), the front in
    red and the winner starred; one cost: the cost against the design's order."""
    study = folder.study
    designs = [r for r in folder.records if r.stage in ("screen", "polish")]
    if not designs:
        return {
            "data": [],
            "layout": {**base_layout("", ""), "annotations": [note("no design yet")]},
        }
    two = len(study.minimize) >= 2

    def xy(records):
        records = [r for r in records if _finite(r.objectives)]
        if two:
            return [r.objectives[0] for r in records], [r.objectives[1] for r in records]
        return [r.number for r in records], [r.objectives[0] for r in records]

    traces = []
    for name, records, style in (
        (
            "fails a requirement",
            [r for r in designs if not r.feasible],
            {"color": "#bdbdbd", "size": 6},
        ),
        ("feasible", [r for r in designs if r.feasible], {"color": "#1976d2", "size": 7}),
        ("front", list(folder.front), {"color": "#d32f2f", "size": 9}),
    ):
        x, y = xy(records)
        traces.append(
            {
                "type": "scatter",
                "mode": "markers",
                "name": name,
                "x": x,
                "y": y,
                "text": [f"design {r.number}" for r in records if _finite(r.objectives)],
                "marker": style,
            }
        )
    if folder.winner is not None:
        x, y = xy([folder.winner])
        if two or folder.winner.of >= 0:
            x = x if two else [folder.winner.of]
        traces.append(
            {
                "type": "scatter",
                "mode": "markers",
                "name": "winner (confirmed)",
                "x": x,
                "y": y,
                "marker": {"symbol": "star", "size": 14, "color": "#ffb300"},
            }
        )
    x_title = study.minimize[0] if two else "design (order run)"
    y_title = study.minimize[1] if two else study.minimize[0]
    layout = base_layout(x_title, y_title, showlegend=True, legend={"orientation": "h", "y": -0.3})
    layout["yaxis"]["type"] = "log" if not two else "linear"
    layout["margin"] = {"l": 60, "r": 12, "t": 8, "b": 80}
    return {"data": traces, "layout": layout}


def design_rows(folder: StudyFolder) -> list[dict[str, Any]]:
    """One row per front design (the winner first): its number, its variables, its costs, each
    requirement's value and margin, its confirmation, and the envelope point where it meets its
    requirements least (what "Open" shows)."""
    study = folder.study
    confirmed = {r.of: r for r in folder.confirmed}
    chosen = list(folder.front)
    if folder.winner is not None:
        of = folder.winner.of if folder.winner.stage == "confirm" else folder.winner.number
        chosen.sort(key=lambda r: r.number != of)
    rows = []
    for rec in chosen:
        rel = [
            m / max(abs(q.bound), 1e-12)
            for q, m in zip(study.requirements, rec.margins, strict=True)
        ]
        binding = min(range(len(rel)), key=lambda i: rel[i]) if rel else 0
        point = worst_point(study, rec, binding) if rel else 0
        conf = confirmed.get(rec.number)
        rows.append(
            {
                "number": rec.number,
                "params": ", ".join(f"{k} = {_num(v)}" for k, v in rec.params.items()),
                "costs": ", ".join(
                    f"{k} = {_num(v)}" for k, v in zip(study.minimize, rec.objectives, strict=True)
                ),
                "requirements": [
                    f"{q.text()}: {_num(v)} (margin {_num(m)})"
                    for q, v, m in zip(study.requirements, rec.values, rec.margins, strict=True)
                ],
                "binding": study.requirements[binding].text() if rel else "",
                "point": point,
                "point_text": ", ".join(f"{k} = {v}" for k, v in study.envelope[point].items()),
                "confirmed": "not confirmed"
                if conf is None
                else (
                    "confirmed at " + conf.preset if conf.feasible else "fails at " + conf.preset
                ),
            }
        )
    return rows


def _num(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)
