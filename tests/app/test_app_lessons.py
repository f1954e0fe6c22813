"""Lessons (app.logic.lessons): each opens in one call, sets what it says (controls, mode, display,
selected pixels), shows its card, and every number on its card is computed again here from the
simulation; leaving a lesson keeps the scene.

A card's figures are checked as the page shows them: the card rendered with the figures computed
here must be the card rendered with the record's figures, character for character (the format
of each figure, ``:.1f``, ``:,``, is the precision the card claims).
"""

from __future__ import annotations

import math
import re
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy import signal
from support.app_helpers import ANYTHING, change, settle

import simcore
from app.engine import Engine
from app.logic.flyaround import FlyaroundPoses
from app.logic.lessons import BY_KEY, LESSON_TARGET, LESSONS, PAPER_SETTINGS, lesson_plan
from app.logic.links import controls_from_link
from app.logic.scene_map import resolved_materials, scene_from_controls
from app.main import LmapdApp
from app.payloads.encode import si_text
from app.state import COLOR_BY, IMAGE_KINDS, MAX_SELECTED_PIXELS, controls_from_scene
from simcore import materials, reproduce
from simcore.atlas import attitude_grid
from simcore.constants import C

PANELS = ("solar_L", "solar_R")


@pytest.fixture(scope="module")
def app():
    scene = simcore.load_scene()
    lmapd = LmapdApp(scene, engine=Engine(scene), flow_control=False, debounce_s=0.0)
    lmapd.state.ready()
    settle(lmapd)
    yield lmapd
    lmapd.logic.runner.close()


@pytest.fixture(scope="module")
def pipeline():
    return simcore.Pipeline()


def open_lesson(app, key: str) -> simcore.Result:
    app.server.controller.trigger_fn("open_lesson")(key)  # what the lesson's button calls
    settle(app)
    return app.logic.last_frame.result


def variant(app, pipeline, key: str, **changes) -> simcore.Result:
    """The lesson's scene with some link settings changed (``fly_t_s``: another fly-around
    frame), simulated as the app builds it."""
    lesson = BY_KEY[key]
    fly_t_s = changes.pop("fly_t_s", lesson.fly_t_s)
    settings = {**lesson.link_settings, **changes}
    controls, messages = controls_from_link(settings, app.logic.panel.initial)
    assert messages == []
    scene = scene_from_controls(app.logic.base_scene, controls)
    if lesson.mode == "flyaround":
        scene = simcore.with_overrides(scene, FlyaroundPoses().overrides(fly_t_s, lesson.fly_j2))
    return pipeline.run(scene)


# -- what the figures are made of --------------------------------------------------------------
def pixel_parts(result: simcore.Result) -> dict[int, set[str]]:
    """Flat pixel index -> the parts its sub-rays hit first (refined pixels: their 64)."""
    names = result.target.part_names
    return {
        p: {names[k] for k in parts.tolist() if k >= 0}
        for p, parts in reproduce.subray_parts(result).items()
    }


def on_parts(result: simcore.Result, names) -> np.ndarray:
    """(lit pixels,) bool: the pixel sees one of the parts ``names``."""
    parts = pixel_parts(result)
    return np.array([bool(parts[int(p)] & set(names)) for p in result.echo.pixel])


def incidence_deg(result: simcore.Result, names) -> float:
    """The median incidence angle [deg] of the sub-rays that hit the parts ``names``."""
    wanted = [result.target.part_names.index(n) for n in names]
    cosines = []
    for block in result.hits.blocks():
        hit = block.face >= 0
        part = np.where(hit, result.target.face_part[np.maximum(block.face, 0)], -1)
        cosines.append(block.cos_theta[np.isin(part, wanted)])
    return float(np.degrees(np.arccos(np.median(np.concatenate(cosines)))))


def peaks_m(result: simcore.Result, row: int, col: int) -> list[float]:
    """The ranges [m] of the peaks of pixel (row, col)'s band-limited echo (those counted by
    ``reproduce.n_peaks``: at least 15 % of the maximum high and as prominent)."""
    w = result.waveform(row, col)
    top = float(w.filtered_w.max())
    found, _ = signal.find_peaks(w.filtered_w, height=0.15 * top, prominence=0.15 * top)
    return [0.5 * C * (float(w.t_s[i]) - result.echo.shape.t_peak_s) for i in found]


def n_double(result: simcore.Result) -> int:
    """Pixels whose echo has two or more peaks."""
    n = result.pixels
    return sum(
        reproduce.n_peaks(result.waveform(*divmod(int(p), n)).filtered_w) >= 2
        for p in result.echo.pixel
    )


def snr_at(result: simcore.Result, row: int, col: int) -> float:
    i = int(np.searchsorted(result.echo.pixel, row * result.pixels + col))
    assert result.echo.pixel[i] == row * result.pixels + col
    return float(result.receiver.snr[i])


def summary(result: simcore.Result, key: str):
    return result.summary()[key]


# -- each lesson's figures, computed -----------------------------------------------------------
def part_range_m(result: simcore.Result, row: int, col: int) -> dict[str, float]:
    """Part -> the median range [m] of pixel (row, col)'s sub-rays that hit it."""
    names, face_part = result.target.part_names, result.target.face_part
    for block in result.hits.blocks():
        found = np.flatnonzero(block.pixel == row * result.pixels + col)
        if len(found):
            face, range_m = block.face[found[0]], block.range_m[found[0]]
            part = np.where(face >= 0, face_part[np.maximum(face, 0)], -1)
            return {names[k]: float(np.median(range_m[part == k])) for k in set(part) - {-1}}
    raise AssertionError(f"pixel ({row}, {col}) is in no block")


def figures_double_peak(app, pipeline, result) -> dict:
    (r1, c1), (r2, c2) = BY_KEY["double-peak"].selection
    for r, c in ((r1, c1), (r2, c2)):  # the dish (cover) in front of the structure behind it
        depth = part_range_m(result, r, c)
        assert set(depth) == {"cover", "default #2"} and depth["cover"] < depth["default #2"]
    for pitch_deg, part in ((1.0, "cover"), (-1.0, "default #2")):  # what the card asks to try
        pitched = variant(app, pipeline, "double-peak", pitch_deg=pitch_deg)
        for r, c in ((r1, c1), (r2, c2)):
            (peak_m,) = peaks_m(pitched, r, c)  # one peak, at that part's depth
            assert abs(peak_m - part_range_m(pitched, r, c)[part]) < 0.3
    near_m, far_m = peaks_m(result, r1, c1)
    near2_m, far2_m = peaks_m(result, r2, c2)
    shape = result.echo.shape
    t_s = shape.t0_s + shape.step_s * np.arange(len(shape.filtered))
    pulse_s = reproduce.fwhm_s(t_s, shape.filtered)
    return {
        "near_m": near_m,
        "far_m": far_m,
        "gap_m": far_m - near_m,
        "gap2_m": far2_m - near2_m,
        "gap_ns": 2 * (far_m - near_m) / C * 1e9,
        "pulse_ns": pulse_s * 1e9,
        "pulse_m": 0.5 * C * pulse_s,
        "range_m": result.waveform(r1, c1).range_m,
        "n_double": n_double(result),
        "n_lit": len(result.echo.pixel),
    }


def figures_panels_azimuth(app, pipeline, result) -> dict:
    lesson = BY_KEY["panels-azimuth"]
    on = on_parts(result, PANELS)
    detected = result.detection.detected
    panel = materials.LIBRARY["solar_panel"]
    inc_left, inc_right = (incidence_deg(result, [n]) for n in PANELS)
    # the record's selection: a pixel of each panel, the left one first
    parts = pixel_parts(result)
    (rl, cl), (rr, cr) = lesson.selection
    assert parts[rl * result.pixels + cl] == {"solar_L"}
    assert parts[rr * result.pixels + cr] == {"solar_R"}

    def rho(deg: float) -> float:  # Eq. 6 at ``deg`` over its value at normal incidence
        cos = np.cos(np.radians([deg, 0.0]))
        value = materials.brdf(cos, panel.A, panel.B, panel.m, panel.s)
        return float(value[0] / value[1])

    def panel_points(azimuth_deg: float) -> tuple[int, int]:
        other = variant(app, pipeline, "panels-azimuth", azimuth_deg=azimuth_deg)
        seen = on_parts(other, PANELS)
        return int(seen.sum()), int((seen & other.detection.detected).sum())

    bright = variant(app, pipeline, "panels-azimuth", azimuth_deg=5.0, pulse_energy_j=5e-3)
    seen = on_parts(bright, PANELS)  # the card's "raise the Pulse energy": the panels are back
    assert (seen & bright.detection.detected).sum() > 0.95 * seen.sum()
    n0, det0 = panel_points(0.0)
    az_more = 5.0  # the azimuth the card asks to try
    _, det_more = panel_points(az_more)
    return {
        "az": lesson.link_settings["azimuth_deg"],
        "energy_mj": energy_mj(lesson),
        "n_panel": int(on.sum()),
        "det": int((on & detected).sum()),
        "det_left": int((on_parts(result, ["solar_L"]) & detected).sum()),
        "det_right": int((on_parts(result, ["solar_R"]) & detected).sum()),
        "n_left": int(on_parts(result, ["solar_L"]).sum()),
        "n_right": int(on_parts(result, ["solar_R"]).sum()),
        "inc_left": inc_left,
        "inc_right": inc_right,
        "rho_left": 100 * rho(inc_left),
        "rho_right": 100 * rho(inc_right),
        "lobe_deg": math.degrees(math.atan(panel.s)),
        "spec": panel.A,
        "diffuse": panel.B,
        "n0": n0,
        "det0": det0,
        "az_more": az_more,
        "det_more": det_more,
    }


def energy_mj(lesson) -> float:
    return lesson.link_settings["pulse_energy_j"] / 1e-3


def figures_distance(app, pipeline, result) -> dict:
    lesson = BY_KEY["distance"]
    d_m = lesson.link_settings["distance_m"]
    d_ref_m, d_close_m = 500.0, 250.0
    ref = variant(app, pipeline, "distance", distance_m=d_ref_m)
    close = variant(app, pipeline, "distance", distance_m=d_close_m)
    parts = pixel_parts(result)
    sel = lesson.selection
    assert [parts[r * result.pixels + c] for r, c in sel] == [
        {"solar_L"},
        {"default #2", "foil"},
        {"cover"},
    ]
    snr_panel, snr_bus, snr_dish = (snr_at(result, r, c) for r, c in sel)
    assert not result.waveform(*sel[2]).detected  # the dish pixel gives no point
    # close in the signal's own shot noise dominates the noise at the peak, far out it does not
    for where, lo, hi in ((ref, 2.0, np.inf), (result, 1.0, 1.5)):
        ratio_pk = np.median(where.receiver.sigma_pk_a) / where.receiver.noise_figures["sigma_n_a"]
        assert lo < ratio_pk < hi
    assert max(result.target.extents_m) > d_close_m * close.scene.receive.fov_rad
    ratio = d_m / d_ref_m
    hit_ref = summary(ref, "n_hit_pixels")
    return {
        "d": d_m,
        "d_ref": d_ref_m,
        "hit": summary(result, "n_hit_pixels"),
        "pts": summary(result, "n_target_points"),
        "hit_ref": hit_ref,
        "pts_ref": summary(ref, "n_target_points"),
        "snr_panel": snr_panel,
        "snr_bus": snr_bus,
        "snr_dish": snr_dish,
        "tnr": lesson.link_settings["tnr"],
        "ratio": ratio,
        "ratio_sq": ratio**2,
        "hit_scaled": hit_ref / ratio**2,
        "snr": summary(result, "snr_median"),
        "snr_ref": summary(ref, "snr_median"),
        "d_close": d_close_m,
        "fov_close": d_close_m * close.scene.receive.fov_rad,
        "hit_close": summary(close, "n_hit_pixels"),
        "hit_close_r2": round(hit_ref * (d_ref_m / d_close_m) ** 2),
        "out": summary(result, "n_outliers"),
        "out_ref": summary(ref, "n_outliers"),
    }


def figures_tnr_trade(app, pipeline, result) -> dict:
    lesson = BY_KEY["tnr-trade"]
    tnr = lesson.link_settings["tnr"]
    figures = {
        "tnr": tnr,
        "energy_mj": energy_mj(lesson),
        "gate_m": result.scene.timing.range_gate_m,
        "n_lit": summary(result, "n_lit_pixels"),
        "snr_px": snr_at(result, *lesson.selection[0]),
        "snr_med": summary(result, "snr_median"),
    }
    for name, value in (("4", tnr), ("5", tnr + 1), ("6", tnr + 2), ("8", tnr + 4)):
        other = result if value == tnr else variant(app, pipeline, "tnr-trade", tnr=value)
        if name != "4":
            figures[f"tnr{name}"] = value
        figures[f"out{name}"] = summary(other, "n_outliers")
        figures[f"drop{name}"] = summary(other, "n_dropped")
        if name in ("4", "5", "6"):
            figures[f"nf{name}"] = summary(other, "n_false_crossings_expected")
    return figures


def figures_pixel_count(app, pipeline, result) -> dict:
    lesson = BY_KEY["pixel-count"]
    n, n_ref = lesson.link_settings["pixels"], 256
    ref = variant(app, pipeline, "pixel-count", pixels=n_ref)
    fov_rad = result.scene.receive.fov_rad
    d_m = result.scene.pose.distance_m
    parts = pixel_parts(result)
    for r, c in lesson.selection:
        assert parts[r * n + c] == {"cover", "default #2"} and len(peaks_m(result, r, c)) == 2
    return {
        "n": n,
        "n_ref": n_ref,
        "d": d_m,
        "cm": 100 * d_m * fov_rad / n,
        "cm_ref": 100 * d_m * fov_rad / n_ref,
        "fov_mrad": 1e3 * fov_rad,
        "ifov_mrad": 1e3 * fov_rad / n,
        "pts": summary(result, "n_target_points"),
        "pts_ref": summary(ref, "n_target_points"),
        "dbl": n_double(result),
        "n_lit": summary(result, "n_lit_pixels"),
        "energy_mj": energy_mj(lesson),
        "ratio": (n_ref / n) ** 2,
        "snr": summary(result, "snr_median"),
        "snr_ref": summary(ref, "snr_median"),
        "out": summary(result, "n_outliers"),
        "out_ref": summary(ref, "n_outliers"),
    }


def figures_flyaround_edge_on(app, pipeline, result) -> dict:
    lesson = BY_KEY["flyaround-edge-on"]
    t0_s, t_again_s = 0.0, 4500.0
    on = on_parts(result, PANELS)
    detected = result.detection.detected
    rim = on_parts(result, ["solar_edge"])
    start = variant(app, pipeline, "flyaround-edge-on", fly_t_s=t0_s)
    again = variant(app, pipeline, "flyaround-edge-on", fly_t_s=t_again_s)
    on0 = on_parts(start, PANELS)
    inc = incidence_deg(result, PANELS)
    parts = pixel_parts(result)
    (r1, c1), (r2, c2) = lesson.selection
    n = result.pixels
    assert parts[r1 * n + c1] == {"solar_L", "solar_edge"} and parts[r2 * n + c2] == {"solar_L"}
    i1, i2 = (int(np.searchsorted(result.echo.pixel, r * n + c)) for r, c in lesson.selection)
    assert detected[i1] and not detected[i2]
    columns = np.unique(result.echo.pixel[on] % n, return_counts=True)[1]
    assert columns.max() <= 2  # "a line a pixel or two high"
    return {
        "t": lesson.fly_t_s,
        "d": result.scene.pose.distance_m,
        "fov_m": result.scene.pose.distance_m * result.scene.receive.fov_rad,
        "n_px": int(on.sum()),
        "n_det": int((on & detected).sum()),
        "n_rim": int((on & rim & detected).sum()),
        "inc": inc,
        "inc_rim": incidence_deg(result, ["solar_edge"]),
        "graze": 90.0 - inc,
        "t0": t0_s,
        "inc0": incidence_deg(start, PANELS),
        "n_px0": int(on0.sum()),
        "n_det0": int((on0 & start.detection.detected).sum()),
        "t_again": t_again_s,
        "inc_again": incidence_deg(again, PANELS),
    }


def figures_day_night(app, pipeline, result) -> dict:
    lesson = BY_KEY["day-night"]
    night = variant(app, pipeline, "day-night", **{"sun.mode": "none"})
    fw_narrow_nm = 1.0
    narrow = variant(app, pipeline, "day-night", **{"receive.filter_width_m": fw_narrow_nm * 1e-9})
    power_w = result.background.power_w
    n = result.pixels
    earth_only = result.background.earth & ~result.hits.hit_pixel_mask.reshape(n, n)
    parts = pixel_parts(result)
    (rp, cp), (rd, cd) = lesson.selection
    assert parts[rp * n + cp] == {"solar_L"} and parts[rd * n + cd] == {"cover"}
    names = [trace["name"] for trace in app.state.waveforms["data"]]
    background = f"background {si_text(power_w[rp, cp], 'W')} (steady: AC-coupled out)"
    assert any(n == background or n == f"{background} (right axis)" for n in names)
    noise = result.receiver.noise_figures
    fw_nm = result.scene.receive.filter_width_m / 1e-9
    return {
        "sun_angle": summary(result, "sun_angle_deg"),
        "sunlit": summary(result, "n_sunlit_pixels"),
        "hit": summary(result, "n_hit_pixels"),
        "bg_panel_nw": 1e9 * power_w[rp, cp],
        "bg_dish_nw": 1e9 * power_w[rd, cd],
        "bg_earth_nw": 1e9 * float(np.median(power_w[earth_only])),
        "fw": fw_nm,
        "share_max": 100 * noise["background_noise_share_max"],
        "share_med": 100 * noise["background_noise_share_median"],
        "out": summary(result, "n_outliers"),
        "drop": summary(result, "n_dropped"),
        "out_night": summary(night, "n_outliers"),
        "drop_night": summary(night, "n_dropped"),
        "fw_narrow": fw_narrow_nm,
        "fw_ratio": fw_nm / fw_narrow_nm,
        "share_narrow": 100 * narrow.receiver.noise_figures["background_noise_share_max"],
        "out_narrow": summary(narrow, "n_outliers"),
    }


def figures_lm_vs_gm(app, pipeline, result) -> dict:
    lesson = BY_KEY["lm-vs-gm"]
    lm_energy_mj = 5.0
    lm = variant(app, pipeline, "lm-vs-gm", **{"receiver.kind": "lm_apd"})
    bright = variant(
        app, pipeline, "lm-vs-gm", **{"receiver.kind": "lm_apd", "pulse_energy_j": 5e-3}
    )
    (row, col), n = lesson.selection[0], result.pixels
    assert result.waveform(row, col).detected and pixel_parts(result)[row * n + col] == {"solar_L"}
    names = [trace["name"] for trace in app.state.waveforms["data"]]
    assert any(n.startswith(f"({row}, {col}) measured counts") for n in names)  # photon histogram

    def range_error_m(r: simcore.Result) -> float:
        d = r.detection
        return float(np.median(np.abs(d.range_m - d.range_true_m)[d.detected]))

    d = result.detection
    assert np.median((d.range_m - d.range_true_m)[d.detected]) < 0  # early: the onset
    # the card: the error, as the stats name it, exceeds the median range sigma beside it
    rows = {row["label"]: row["value"] for row in app.state.stats}
    assert rows["Median range error (against the noise-free range)"] == (
        f"{range_error_m(result) * 100:.3g} cm"
    )
    assert range_error_m(result) > summary(result, "range_sigma_m_median")
    return {
        "d": result.scene.pose.distance_m,
        "energy_mj": energy_mj(lesson),
        "gm_pts": summary(result, "n_target_points"),
        "lit": summary(result, "n_lit_pixels"),
        "pulses": result.scene.gm.pulses,
        "lm_pts": summary(lm, "n_target_points"),
        "lm_out": summary(lm, "n_outliers"),
        "pe": result.receiver.noise_figures["signal_pe_median"],
        "lm_snr": summary(lm, "snr_median"),
        "dead_ns": result.scene.gm.dead_time_s * 1e9,
        "gm_err": range_error_m(result),
        "lm_err": range_error_m(bright),
        "lm_energy_mj": lm_energy_mj,
        "lm_pts_bright": summary(bright, "n_target_points"),
    }


def figures_panels_vanish(app, pipeline, result) -> dict:
    """From the map the lesson computes (its 45-degree grid: the rows of a finer level hold
    them too), then stopped: the finer levels are not the card's."""
    lesson = BY_KEY["panels-vanish"]
    maps = app.logic.attitudes
    assert app.state.attitudes_metric == "n_target_points"
    deadline = time.monotonic() + 120
    while (maps.level is None or maps.level.grid.step_deg > 45) and time.monotonic() < deadline:
        time.sleep(0.02)
    level = maps.level
    maps.stop()
    assert maps.runner.wait_idle(60)
    grid = attitude_grid(45.0)
    rows = {a: level.rows[a] for a in grid.attitudes()}
    light = maps.map_scene
    assert light.detector.pixels == 32 and light.fidelity == result.scene.fidelity

    def points(pitch: float, azimuth: float) -> int:
        return rows[(pitch, azimuth)]["n_target_points"]

    az_edge = lesson.figures["az_edge"]
    meridian = [a for a in rows if abs(a[0]) == 90 or a[1] in (az_edge, 360 - az_edge)]
    solar = [a for a, r in rows.items() if r["dominant_material"] == "solar_panel"]
    assert not set(solar) & set(meridian)  # "and in none on that meridian"
    assert max(r["n_target_points"] for r in rows.values()) == points(0.0, 0.0)  # the brightest
    return {
        "px": light.detector.pixels,
        "n_cells": len(grid),
        "step": grid.step_deg,
        "p0": 0.0,
        "az0": 0.0,
        "n_head": points(0.0, 0.0),
        "n_back": points(0.0, 180.0),
        "az_back": 180.0,
        "az_edge": az_edge,
        "n_edge_max": max(points(*a) for a in meridian),
        "n_solar": len(solar),
    }


FIGURES = {
    "double-peak": figures_double_peak,
    "panels-azimuth": figures_panels_azimuth,
    "distance": figures_distance,
    "tnr-trade": figures_tnr_trade,
    "pixel-count": figures_pixel_count,
    "flyaround-edge-on": figures_flyaround_edge_on,
    "day-night": figures_day_night,
    "lm-vs-gm": figures_lm_vs_gm,
    "panels-vanish": figures_panels_vanish,
}


# -- the tests ---------------------------------------------------------------------------------
def test_there_are_at_least_six_lessons_each_with_a_card_and_a_section_to_read():
    assert len(LESSONS) >= 6 and len(BY_KEY) == len(LESSONS)
    for lesson in LESSONS:
        assert re.fullmatch(r"[a-z0-9-]+", lesson.key)
        assert lesson.title and lesson.look and lesson.why and lesson.try_next
        assert re.fullmatch(r"docs/physics\.md#[\w-]+", lesson.reference)  # checked to resolve
        assert lesson.reference_title  # by tests/test_physics_doc.py
        assert 1 <= len(lesson.selection) <= MAX_SELECTED_PIXELS
        assert lesson.color_by in COLOR_BY and lesson.image_kind in IMAGE_KINDS
        assert lesson.mode in ("single", "flyaround")


def test_every_number_on_a_card_is_one_of_its_figures():
    """No digit in a template outside a placeholder (but the equations' and tables' numbers),
    and every figure is used."""
    for lesson in LESSONS:
        assert lesson.basic, lesson.key  # every card has its text for a reader of 14-16
        text = lesson.basic + lesson.look + lesson.why + lesson.try_next
        fields = set(re.findall(r"\{(\w+)", text))
        assert fields == set(lesson.figures), lesson.key
        words = re.sub(r"\{[^}]*\}|Eqs?\. \d+(-\d+)?|Table \d+", "", text)
        assert not re.search(r"\d", words), (lesson.key, re.findall(r"\S*\d\S*", words))


def test_the_paper_settings_are_the_paper_scene():
    scene = simcore.load_scene()
    model = simcore.load_target(scene.target)
    initial = controls_from_scene(scene, resolved_materials(model, scene))[0]
    controls, messages = controls_from_link(PAPER_SETTINGS, initial)
    assert messages == [] and controls == initial
    assert scene_from_controls(scene, controls) == scene_from_controls(scene, initial)


@pytest.mark.parametrize("key", [x.key for x in LESSONS])
def test_a_lesson_opens_sets_what_it_says_and_its_figures_hold(app, pipeline, key):
    lesson = BY_KEY[key]
    result = open_lesson(app, key)
    state = app.state
    plan = lesson_plan(lesson, app.logic.panel.initial)
    assert plan.messages == [] and state.input_message == ""
    assert {k: state[k] for k in plan.controls.as_state()} == plan.controls.as_state()
    for name in ("pulse_energy_mj", "filter_width_nm", "distance_m", "tnr"):
        assert len(repr(state[name])) <= 6, (name, state[name])  # 0.1 mJ, not 0.09999999999
    assert (state.mode, state.fly_t_s, state.fly_j2) == (lesson.mode, lesson.fly_t_s, False)
    assert (state.color_by, state.image_kind) == (lesson.color_by, lesson.image_kind)
    assert state.selected_pixels == [list(p) for p in lesson.selection]
    assert len(state.waveforms["data"]) > 0
    assert state.lesson == lesson.card() and state.lesson["note"] == ""
    assert result.pixels == lesson.link_settings["pixels"]
    computed = FIGURES[key](app, pipeline, result)
    assert set(computed) == set(lesson.figures)
    assert lesson.card(computed) == lesson.card(), f"computed figures: {computed}"


def test_leaving_a_lesson_keeps_the_scene_the_mode_and_the_selection(app):
    open_lesson(app, "flyaround-edge-on")
    before = {k: app.state[k] for k in (*app.logic.panel.current.as_state(), "mode", "fly_t_s")}
    selected, generation = app.state.selected_pixels, app.logic.runner.generation
    frame = app.logic.last_frame
    app.server.controller.trigger_fn("leave_lesson")()  # the card's button
    settle(app)
    assert app.state.lesson is None
    assert {k: app.state[k] for k in before} == before and app.state.selected_pixels == selected
    assert app.logic.runner.generation == generation and app.logic.last_frame is frame
    change(app, fly_t_s=1800.0)  # the user goes on from there
    assert app.logic.last_frame.result.scene.orbit.time_s == 1800.0
    change(app, mode="single")


def test_a_control_changed_in_a_lesson_keeps_its_card_and_reopening_restores_it(app):
    open_lesson(app, "tnr-trade")
    change(app, tnr=6.0)
    assert (
        app.state.lesson["key"] == "tnr-trade" and app.logic.last_frame.result.scene.timing.tnr == 6
    )
    app.logic.on_pixel_click(10, 10)  # the user's own pixel
    generation = app.logic.runner.generation
    open_lesson(app, "tnr-trade")
    assert app.state.tnr == 4.0 and app.state.selected_pixels == [[124, 141]]
    assert app.logic.runner.generation == generation + 1  # one new frame
    names = [trace["name"] for trace in app.state.waveforms["data"]]
    assert any("124" in name and "141" in name for name in names), names


def test_opening_the_same_lesson_twice_computes_its_frame_again_for_its_selection(app):
    open_lesson(app, "double-peak")
    app.logic.on_pixel_click(5, 5)
    assert app.state.selected_pixels == [[5, 5]]
    generation = app.logic.runner.generation
    open_lesson(app, "double-peak")  # the same scene: no control changes, the selection does
    assert app.logic.runner.generation == generation + 1
    assert app.state.selected_pixels == [[113, 131], [114, 124]]
    assert len(app.state.waveforms["data"]) > 2


@pytest.mark.parametrize(
    "key", ["nope", "", None, 3, 2.5, ["double-peak"], {"key": "x"}, "x" * 5000, "DOUBLE-PEAK"]
)
def test_an_unknown_lesson_changes_nothing_and_says_so(app, key):
    open_lesson(app, "pixel-count")
    controls, generation = app.logic.panel.current, app.logic.runner.generation
    app.server.controller.trigger_fn("open_lesson")(key)
    assert app.logic.panel.current == controls and app.logic.runner.generation == generation
    assert app.state.input_message.startswith("Lessons: no lesson ")
    assert len(app.state.input_message) < 120 and app.state.lesson["key"] == "pixel-count"
    app.state.input_message = ""


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    args=st.lists(ANYTHING, max_size=3),
    kwargs=st.dictionaries(st.just("key") | st.text(max_size=5), ANYTHING),
)
def test_the_lesson_triggers_take_anything_a_page_sends_without_raising(app, args, kwargs):
    assume(not (args and isinstance(args[0], str) and args[0] in BY_KEY))  # a real lesson
    controls = app.logic.panel.current
    app.server.controller.trigger_fn("open_lesson")(*args, **kwargs)
    app.server.controller.trigger_fn("leave_lesson")(*args, **kwargs)
    assert app.logic.panel.current == controls and app.state.lesson is None
    app.state.input_message = ""


def test_on_another_target_a_lesson_sets_its_controls_and_its_card_says_whose_figures():
    scene = simcore.with_overrides(
        simcore.load_scene(), {"target.mesh": "sphere", "target.size_m": 4.0, "pixels": 32}
    )
    other = LmapdApp(scene, engine=Engine(scene), flow_control=False, debounce_s=0.0)
    other.state.ready()
    settle(other)
    try:
        assert LESSON_TARGET not in other.state.target_name
        result = open_lesson(other, "distance")
        assert result.scene.pose.distance_m == 3000.0 and result.pixels == 256
        assert LESSON_TARGET in other.state.lesson["note"]
        plan = lesson_plan(BY_KEY["distance"], other.logic.panel.initial)
        assert plan.controls == other.logic.panel.current
    finally:
        other.logic.runner.close()
