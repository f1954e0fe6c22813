"""Downloads in a real Chromium: each button saves a file that the project's readers read back
(the cloud with the page's point count, the waveforms with units, the scene that lmapd simulate
takes)."""

from __future__ import annotations

import pytest
from support.launch import JS_STATE, wait_first_frame, wait_settled

import simcore
from simcore import io as simcore_io

pytestmark = pytest.mark.browser


def download(page, css: str, folder):
    with page.expect_download() as info:
        page.locator(f".{css}").click()
    path = folder / info.value.suggested_filename
    info.value.save_as(path)
    return path


def test_every_download_reads_back(page, app_url, tmp_path):
    page.goto(app_url)
    wait_first_frame(page)
    wait_settled(page)
    count = int(page.locator(".point-count").inner_text().split()[0].replace(",", ""))
    for css, suffix in (("export-ply", ".ply"), ("export-las", ".las")):
        path = download(page, css, tmp_path)
        assert path.suffix == suffix and len(simcore_io.read_cloud(path)) == count
    csv_path = download(page, "export-csv", tmp_path)
    header = next(ln for ln in csv_path.read_text().splitlines() if not ln.startswith("#"))
    assert header == "row,col,time_s,power_w,filtered_w,threshold_w,range_m,detected"
    scene = simcore.load_scene(str(download(page, "export-toml", tmp_path)))
    shown = {k: page.evaluate(JS_STATE, k) for k in ("pixels", "distance_m", "tnr")}
    assert (scene.detector.pixels, scene.pose.distance_m, scene.timing.tnr) == tuple(shown.values())
