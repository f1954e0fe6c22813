"""A frame's per-ray and per-pixel work split over its threads in chunks (the ray cast's chunks
turning, casting and shading their own rays; the echo stage's chunks of lit pixels making their
elements, merged to different widths and padded) and its compiled kernels run in parallel however
small their work (their serial thresholds set to 0): each pixel's figures never depend on where
the chunks fall, so the hits, echoes and clouds of 1 and 3 threads are equal bit for bit."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import simcore
from simcore import parallel, pointcloud
from simcore.echo import features as echo_features
from simcore.echo import stage as echo_stage
from simcore.receivers.lm_apd import detection

CASES = {
    # the interactive preset: refined blocks of 64 sub-rays, cell spread, corners, merging
    "interactive": {"pixels": 48, "preset": "interactive", "pitch_deg": 30.0},
    # 16 sub-rays merged within the window, no refinement
    "merged": {"pixels": 48, "fidelity.subrays": 16, "fidelity.merge_window": 0.5},
    "paper_delays": {"pixels": 48, "paper_forms": ("eq29_one_way",), "fidelity.cell_spread": True},
    # by day: the stops of noise and echoes, each pixel its own rate
    "daylight": {"pixels": 48, "sun.mode": "manual", "pitch_deg": 35.0, "tnr": 4.0},
}


def frame(overrides: dict, threads: int, small_chunks: bool, monkeypatch):
    if small_chunks:
        monkeypatch.setattr(echo_stage, "ELEMENT_CHUNK_PIXELS", 64)
        monkeypatch.setattr(echo_features, "SERIAL_BELOW_PIXELS", 0)
        monkeypatch.setattr(detection, "STOPS_SERIAL_BELOW", 0)
        monkeypatch.setattr(pointcloud, "TRUTH_SERIAL_BELOW", 0)
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
    for name, values in result.attributes.items():
        out[f"cloud.{name}"] = np.asarray(values)
    out["outliers"] = result.detection.outliers.pixel
    return out


@pytest.mark.parametrize("case", list(CASES))
def test_hits_echoes_and_clouds_do_not_depend_on_the_chunks(case, monkeypatch):
    one = arrays(frame(CASES[case], 1, False, monkeypatch))
    many = arrays(frame(CASES[case], 3, True, monkeypatch))
    assert one.keys() == many.keys()
    for name, values in one.items():
        assert many[name].shape == values.shape, name
        assert np.array_equal(many[name], values, equal_nan=True), name


@pytest.mark.parametrize("shape", [(4096, 4), (300, 64), (5, 1), (0, 4), (7, 0)])
def test_any_per_row_is_numpys_any_along_rows(shape):
    mask = np.random.default_rng(1).random(shape) < 0.1
    assert np.array_equal(echo_stage.any_per_row(mask), mask.any(axis=1))


def test_small_regions_run_on_one_thread_and_large_ones_on_the_frames():
    before = parallel.threads()
    parallel.set_threads(3)
    try:
        assert parallel.threads_for(100, 65536) == 1
        assert parallel.threads_for(65536, 65536) == 3
        assert parallel.threads_for(0, 0) == 3
    finally:
        parallel.set_threads(before)
