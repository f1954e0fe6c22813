"""The Sun in the app: its control changes only what depends on it, the array image shows the
background, the waveform chart its level and the noise band, the stats its figures."""

from __future__ import annotations

import numpy as np
import pytest
from support.app_helpers import change, small_app, stat


@pytest.fixture(scope="module")
def app():
    with small_app() as lmapd:
        yield lmapd


def test_by_night_the_stats_say_no_background_and_the_chart_has_no_band(app):
    assert stat(app, "Background light") == "none (no Sun)"
    names = [t["name"] for t in app.state.waveforms["data"]]
    assert not any(n.startswith(("background", "noise ±σn")) for n in names)


def test_a_manual_sun_lights_the_target_without_a_new_ray_cast(app):
    change(app, sun_mode="manual", sun_azimuth_deg=20.0, sun_elevation_deg=10.0)
    frame = app.logic.last_frame
    assert frame.result.scene.sun.mode == "manual" and frame.result.scene.sun.azimuth_deg == 20
    assert frame.timings_s["hits"] == 0.0 and frame.timings_s["background"] > 0  # cached rays
    assert frame.result.background.power_w.max() > 0
    assert stat(app, "Median background power (pixels in light)").endswith("W")
    assert "%" in stat(app, "Background share of noise var.")
    power = frame.result.background.power_w
    row, col = (int(i) for i in np.unravel_index(np.argmax(power), power.shape))
    app.logic.on_pixel_click(row, col)  # the brightest pixel's echo
    names = [t["name"] for t in app.state.waveforms["data"]]
    assert any(n.startswith("background") for n in names) and any(
        n.startswith("noise ±σn") for n in names
    )
    assert (
        "sun.mode=manual" in app.state.share_query and "sun.azimuth_deg=20" in app.state.share_query
    )


def test_the_array_image_shows_the_background_and_a_wider_filter_lets_more_in(app):
    change(app, sun_mode="manual", image_kind="background", filter_width_nm=1.0)
    assert app.state.array_image["colorbar"]["title"] == "Background power (log)"
    narrow = app.logic.last_frame.result.background.power_w.max()
    change(app, filter_width_nm=10.0)
    assert app.logic.last_frame.result.scene.receive.filter_width_m == pytest.approx(1e-8)
    assert app.logic.last_frame.result.background.power_w.max() > 5 * narrow
    change(app, sun_mode="none", image_kind="range")
    assert app.logic.last_frame.result.background.power_w.max() == 0
