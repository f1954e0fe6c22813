"""Downloads from the page (app.logic.exports): the cloud reads back with the project's readers,
the waveforms' CSV carries units in its header and the samples of the chart, and the scene's TOML
gives the same points with lmapd simulate; refusals are messages, never files."""

from __future__ import annotations

import csv
import io

import numpy as np
import pytest
from support.app_helpers import small_app

import simcore
from app.logic import exports
from simcore import io as simcore_io


@pytest.fixture(scope="module")
def app():
    with small_app() as lmapd:
        yield lmapd


@pytest.mark.parametrize("fmt", ["ply", "las"])
def test_the_cloud_downloads_and_reads_back_with_the_projects_readers(app, fmt, tmp_path):
    result = app.logic.last_frame.result
    path = tmp_path / f"cloud.{fmt}"
    path.write_bytes(exports.cloud_file(result, fmt))
    back = simcore_io.read_cloud(path)
    assert len(back) == len(result.cloud) > 0
    tolerance_m = 1e-3 if fmt == "las" else 0.0  # LAS stores millimetre integers
    assert np.allclose(back.points, result.cloud.points, rtol=0, atol=tolerance_m)
    assert any("NASA" in c for c in simcore_io.read_cloud_comments(path))


def test_the_waveforms_csv_has_units_in_its_header_and_the_pixels_samples(app):
    result = app.logic.last_frame.result
    row, col = app.state.selected_pixels[0]
    text = app.logic.export_waveforms()
    lines = [ln for ln in text.splitlines() if not ln.startswith("#")]
    table = list(csv.DictReader(io.StringIO("\n".join(lines))))
    assert list(table[0]) == list(exports.WAVEFORM_COLUMNS)
    assert all(
        name in ("row", "col", "detected") or name.endswith(("_s", "_w", "_m")) for name in table[0]
    )
    w = result.waveform(row, col)
    mine = [r for r in table if (int(r["row"]), int(r["col"])) == (row, col)]
    assert len(mine) == len(w.t_s) > 0
    assert np.array_equal([float(r["filtered_w"]) for r in mine], w.filtered_w)


def test_the_scene_toml_gives_the_same_points_with_the_core(app, tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(app.logic.export_scene())
    again = simcore.simulate(simcore.load_scene(str(path)))
    assert np.array_equal(again.cloud.points, app.logic.last_frame.result.cloud.points)


def test_refusals_are_messages_and_no_file(app):
    with pytest.raises(exports.ExportError, match="ply or las"):
        exports.cloud_file(app.logic.last_frame.result, "../../etc/passwd")
    assert (
        app.logic.export_cloud("exe") is None
        and "Download: point clouds" in app.state.error_message
    )
    with app.state:
        app.state.selected_pixels = []
    assert app.logic.export_waveforms() is None
    assert app.state.error_message == "Download: select a pixel on the detector array first"
