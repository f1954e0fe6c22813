"""The Geiger-mode receiver in the app: the switch and its parameters reach the scene, the chart
shows the clicked pixel's photon histogram against the expected counts, the stats say which
receiver ran."""

from __future__ import annotations

import numpy as np
import pytest
from support.app_helpers import change, small_app, stat


@pytest.fixture(scope="module")
def app():
    with small_app() as lmapd:
        yield lmapd


def test_the_linear_mode_array_is_the_default_and_says_so(app):
    assert stat(app, "Receiver") == "linear-mode APD array"
    assert all(t["type"] == "scatter" for t in app.state.waveforms["data"])


def test_the_geiger_mode_switch_and_its_parameters_reach_the_scene(app):
    change(
        app,
        receiver_kind="gm_apd",
        gm_pde=0.5,
        gm_dark_count_rate_hz=2e4,
        gm_dead_time_ns=50.0,
        gm_pulses=20,
        pulse_energy_mj=0.001,
    )
    scene = app.logic.last_frame.result.scene
    assert scene.receiver.kind == "gm_apd" and scene.gm.pde == 0.5 and scene.gm.pulses == 20
    assert scene.gm.dead_time_s == pytest.approx(50e-9) and scene.gm.dark_count_rate_hz == 2e4
    assert stat(app, "Receiver") == "Geiger-mode array, 20 pulses"
    assert float(stat(app, "Echo photoelectrons / pulse")) > 0
    query = app.state.share_query
    assert "receiver.kind=gm_apd" in query and "gm.pulses=20" in query


def test_the_chart_shows_the_pixels_histogram_and_the_expected_counts(app):
    # about one echo photoelectron per pulse: 10 uJ unattenuated, PDE 0.01, 5 km
    change(
        app,
        receiver_kind="gm_apd",
        gm_pulses=50,
        gm_pde=0.01,
        pulse_energy_mj=0.01,
        gm_attenuation_db=0.0,
        distance_m=5000,
    )
    result = app.logic.last_frame.result
    brightest = int(result.echo.pixel[np.argmax(result.receiver.signal_pe)])
    row, col = divmod(brightest, result.pixels)
    app.logic.on_pixel_click(row, col)
    bars, expected, arriving = app.state.waveforms["data"][:3]
    assert bars["type"] == "bar" and "expected (same pulses" in expected["name"]
    assert "without dead time" in arriving["name"]
    bins, counts = result.receiver.histogram.pixel_counts(row * result.pixels + col)
    elsewhere = (
        int(bars["name"].split(", ")[-1].split()[0].replace(",", ""))
        if "more" in bars["name"]
        else 0
    )
    assert sum(bars["y"]) + elsewhere == counts.sum() > 0
    # a weak echo: the counts drawn come near the expected ones (one per pulse at most, the
    # dead time outlasting the gate: 1 - exp(-N) of the N arriving per pulse)
    n_arriving = sum(arriving["y"]) / 50
    assert 0.2 < n_arriving < 5
    want = 50 * (1 - np.exp(-n_arriving))
    assert abs(sum(bars["y"]) - want) < 4 * np.sqrt(want) + 1
    # the expected curve with the dead time says the same within the window's edges
    assert sum(expected["y"]) == pytest.approx(want, rel=0.1)
    assert np.all(np.diff(bars["x"]) > 0)


def test_the_default_geiger_mode_chart_shows_the_measured_counts_at_their_scale(app):
    """Photon-starved or piled up, the measured histogram is drawn on the axis it fills: the
    expected counts with the dead time share it, the counts without dead time get the right-hand
    axis when they would flatten it; the captions and the stats speak of counts, not of one
    flash's SNR and TNR; the time axis reads in whole ns."""
    for overrides in ({"gm_attenuation_db": 50.0}, {"gm_attenuation_db": 0.0}):
        change(
            app,
            receiver_kind="gm_apd",
            gm_pulses=100,
            gm_pde=0.3,
            pulse_energy_mj=5.0,
            distance_m=500,
            **overrides,
        )
        result = app.logic.last_frame.result
        brightest = int(result.echo.pixel[np.argmax(result.receiver.signal_pe)])
        app.logic.on_pixel_click(*divmod(brightest, result.pixels))
        figure = app.state.waveforms
        bars, expected, arriving = figure["data"][:3]
        assert max(bars["y"]) > 0
        left = max(bars["y"] + expected["y"])
        # the measured counts fill at least a third of their axis
        assert max(bars["y"]) > left / 3
        assert sum(expected["y"]) == pytest.approx(sum(bars["y"]), rel=0.25)
        own_axis = max(arriving["y"]) > 2 * left
        assert (arriving.get("yaxis") == "y2") == own_axis
        xaxis = figure["layout"]["xaxis"]
        assert xaxis["tickformat"].startswith(",.") and xaxis["dtick"] > 0
        assert figure["layout"]["xaxis2"]["ticktext"][0].endswith(" m")
        # opened on the echo: every bin with a tenth of the peak's counts in view, the whole
        # window (every bar) a click away
        lo, hi = xaxis["range"]
        peak_x = [x for x, y in zip(bars["x"], bars["y"], strict=True) if y >= max(bars["y"]) / 10]
        assert lo <= min(peak_x) and max(peak_x) <= hi
        menu = figure["layout"]["updatemenus"][0]["buttons"]
        assert [b["label"] for b in menu] == ["Echo", "Whole window"]
        whole_lo, whole_hi = menu[1]["args"][0]["xaxis.range"]
        assert whole_lo <= min(bars["x"]) and max(bars["x"]) <= whole_hi
        assert hi - lo < 0.6 * (whole_hi - whole_lo) and menu[0]["args"][0]["xaxis.range"] == [
            lo,
            hi,
        ]
    assert own_axis  # unattenuated, the brightest pixel piles up
    assert "Photon counts" in app.state.view_text["waveform_title"]
    assert "dead time" in app.state.view_text["waveform_caption"]
    labels = [row["label"] for row in app.state.stats]
    assert "Median SNR" not in labels and "Median count SNR S/√(S+B) (frame)" in labels
    assert not app.state.snr_hist["layout"].get("shapes")  # no TNR line on the count SNR


def test_back_to_linear_mode(app):
    change(app, receiver_kind="lm_apd", pulse_energy_mj=5.0, distance_m=500)
    assert app.logic.last_frame.result.scene.receiver.kind == "lm_apd"
    assert stat(app, "Receiver") == "linear-mode APD array"
    assert "Echo waveforms" in app.state.view_text["waveform_title"]
    assert app.state.snr_hist["layout"]["shapes"]  # the TNR line
