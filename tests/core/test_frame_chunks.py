"""A frame's per-ray and per-pixel work split over its threads in chunks (the ray cast's chunks
turning, casting and shading their own rays; the echo stage's chunks of lit pixels making their
elements, merged to different widths and padded): each pixel's figures never depend on where the
chunks fall, so the hits and echoes of 1 and 3 threads with small chunks are equal bit for bit."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import simcore
from simcore import parallel
from simcore.echo import stage as echo_stage

CASES = {
    # the interactive preset: refined blocks of 64 sub-rays, cell spread, corners, merging
    "interactive": {"pixels": 48, "preset": "interactive", "pitch_deg": 30.0},
    # 16 sub-rays merged within the window, no refinement
    "merged": {"pixels": 48, "fidelity.subrays": 16, "fidelity.merge_window": 0.5},
    "paper_delays": {"pixels": 48, "paper_forms": ("eq29_one_way",), "fidelity.cell_spread": True},
}


def frame(overrides: dict, threads: int, chunk_pixels: int, monkeypatch):
    monkeypatch.setattr(echo_stage, "ELEMENT_CHUNK_PIXELS", chunk_pixels)
    before = parallel.threads()
    parallel.set_threads(threads)
    try:
        return simcore.Pipeline().run(simcore.with_overrides(simcore.Scene(), overrides))
    finally:
        parallel.set_threads(before)


def arrays(result) -> dict[str, np.ndarray]:
    out = {}
    for i, block in enumerate((result.hits.base, result.hits.refined)):
        if block is not None:
            for f in dataclasses.fields(block):
                if getattr(block, f.name) is not None:
                    out[f"hits{i}.{f.name}"] = getattr(block, f.name)
    echo = result.echo
    for name in ("pixel", "arrivals_s", "weights", "material_id", "facet_id"):
        out[f"echo.{name}"] = getattr(echo, name)
    for f in dataclasses.fields(echo.features):
        if getattr(echo.features, f.name) is not None:
            out[f"features.{f.name}"] = getattr(echo.features, f.name)
    out["points"] = result.points
    return out


@pytest.mark.parametrize("case", list(CASES))
def test_hits_and_echoes_do_not_depend_on_the_chunks(case, monkeypatch):
    one = arrays(frame(CASES[case], 1, echo_stage.ELEMENT_CHUNK_PIXELS, monkeypatch))
    many = arrays(frame(CASES[case], 3, 64, monkeypatch))
    assert one.keys() == many.keys()
    for name, values in one.items():
        assert many[name].shape == values.shape, name
        assert np.array_equal(many[name], values, equal_nan=True), name
