"""The classroom's words: every control has glossary entries (TNR, SNR, P_d, FWHM, CFD, pile-up
among them), and a likely echo that gave no point is said to be missed by chance, in the chart's
legend and in the stats."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from support.app_helpers import change, small_app, stat
from support.ideal_receiver import IDEAL, KIND

from app.state import SPECS
from app.ui.glossary import CONTROL_TERMS, GLOSSARY
from simcore import receivers


def test_every_control_has_glossary_entries_and_the_lessons_words_are_there():
    assert set(SPECS) <= set(CONTROL_TERMS)
    assert all(term in GLOSSARY for terms in CONTROL_TERMS.values() for term in terms)
    for word in ("TNR", "SNR", "P_d", "FWHM", "CFD", "Pile-up", "Dead time", "PDE"):
        assert GLOSSARY[word]
    assert CONTROL_TERMS["tnr"][0] == "TNR"


def test_each_receiver_declares_its_words_and_its_half_of_a_shared_one():
    # the Geiger-mode words are gm_apd's; SNR reads the page's lead, then linear, then Geiger mode
    gm_words = dict(receivers.get("gm_apd").glossary)
    assert GLOSSARY["Pile-up"] == gm_words["Pile-up"]
    assert GLOSSARY["SNR"] == " ".join(
        ("Signal-to-noise ratio:", dict(receivers.get("lm_apd").glossary)["SNR"], gm_words["SNR"])
    )
    ideal = dataclasses.replace(
        IDEAL, glossary=(("Ideal threshold", "A fixed power."), ("SNR", "Ideal: the margin."))
    )
    receivers.register(ideal)
    try:
        assert GLOSSARY["Ideal threshold"] == "A fixed power."  # a new entry, after the others
        assert list(GLOSSARY)[-1] == "Ideal threshold"
        assert GLOSSARY["SNR"].endswith(f"{gm_words['SNR']} Ideal: the margin.")  # its half
    finally:
        receivers.unregister(KIND)
    assert "Ideal threshold" not in GLOSSARY


@pytest.fixture(scope="module")
def app():
    with small_app(pixels=48) as lmapd:
        yield lmapd


def test_a_likely_echo_missed_is_said_to_be_missed_by_chance(app):
    # low threshold-to-noise margins: many pixels with P_d between 0.5 and 1 that the noise misses
    change(app, pulse_energy_mj=0.3, distance_m=500, tnr=5.0)
    result = app.logic.last_frame.result
    d = result.detection
    taken = {i for i, _ in stops_taken(result)}  # (a stop a false alarm took is said apart)
    by_chance = ~np.asarray(d.detected) & (np.asarray(d.p_detect) >= 0.5)
    by_chance[list(taken)] = False
    assert by_chance.any()
    assert stat(app, "Missed by chance (P_d ≥ 0.5)") == f"{int(by_chance.sum()):,d}"
    # the cards' "pixels with an echo" has a row of its own
    assert stat(app, "Pixels with an echo (lit)") == f"{len(result.echo.pixel):,d}"
    labels = [row["label"] for row in app.state.stats]
    chance_at = labels.index("Missed by chance (P_d ≥ 0.5)")
    assert chance_at == labels.index("Dropped pixels (missed)") + 2  # after the stops taken
    flat = int(result.echo.pixel[np.flatnonzero(by_chance)[0]])
    row, col = divmod(flat, result.pixels)
    app.logic.on_pixel_click(row, col)
    name = app.state.waveforms["data"][0]["name"]
    p_d = float(d.p_detect[np.flatnonzero(by_chance)[0]])
    assert name == f"({row}, {col}) not detected: P_d {p_d:.2f}, missed by chance this frame"
    weak = ~np.asarray(d.detected) & (np.asarray(d.p_detect) < 0.5)
    if weak.any():  # one too weak for the threshold is not said to be missed by chance
        row, col = divmod(int(result.echo.pixel[np.flatnonzero(weak)[0]]), result.pixels)
        app.logic.on_pixel_click(row, col)
        assert "too weak for the threshold" in app.state.waveforms["data"][0]["name"]


def stops_taken(result) -> list[tuple[int, float]]:
    """(lit index, range [m]) of each echo not detected whose pixel's one stop (K = 1, the
    default) went to a false alarm before it, from the receiver's own stops, pixel by pixel."""
    assert result.scene.timing.max_stops == 1
    d = result.detection
    alarms: dict[int, list[float]] = {}
    for pixel, range_m in zip(d.outliers.pixel.tolist(), d.outliers.range_m.tolist(), strict=True):
        alarms.setdefault(pixel, []).append(range_m)
    taken = []
    for i, pixel in enumerate(result.echo.pixel.tolist()):
        echo_m = float(d.range_true_m[i])
        before = [r for r in alarms.get(pixel, []) if r < echo_m]
        if not d.detected[i] and before:
            assert len(before) == 1  # one stop: the pixel recorded one false alarm at most
            taken.append((i, before[0]))
    return taken


def test_a_pixel_whose_stop_went_to_a_false_alarm_says_so_and_is_counted_apart(app):
    # strong echoes (median SNR about 100) under a low threshold: false alarms in a fifth of
    # the pixels, half of them before the echo; the echoes themselves are all but certain
    change(app, pulse_energy_mj=5.0, distance_m=500, tnr=4.0, sun_mode="none")
    result = app.logic.last_frame.result
    d = result.detection
    taken = stops_taken(result)
    assert len(taken) >= 10
    missed = ~np.asarray(d.detected)
    sure = missed & (np.asarray(result.receiver.snr) > 30.0)  # P_d's draw cannot miss these
    assert sure.sum() >= 10 and set(np.flatnonzero(sure)) <= {i for i, _ in taken}
    assert stat(app, "Taken by a false alarm (its stop used)") == f"{len(taken):,d}"
    chance = missed & (np.asarray(d.p_detect) >= 0.5)
    chance[[i for i, _ in taken]] = False
    assert stat(app, "Missed by chance (P_d ≥ 0.5)") == f"{int(chance.sum()):,d}"
    labels = [row["label"] for row in app.state.stats]
    at = labels.index("Dropped pixels (missed)")
    assert labels[at + 1 : at + 3] == [
        "Taken by a false alarm (its stop used)",
        "Missed by chance (P_d ≥ 0.5)",
    ]
    i, alarm_m = taken[0]
    row, col = divmod(int(result.echo.pixel[i]), result.pixels)
    app.logic.on_pixel_click(row, col)
    name = app.state.waveforms["data"][0]["name"]
    p_d = float(d.p_detect[i])
    assert name == (
        f"({row}, {col}) not detected: taken by a false alarm at {alarm_m:.1f} m (P_d {p_d:.2f})"
    )
    change(app, tnr=5.0)


def test_every_lessons_reference_opens_its_section_of_the_physics_page(app):
    from app.logic.lessons import LESSONS

    assert app.state.physics_available
    for lesson in LESSONS:
        app.logic.physics.open(lesson.reference)
        section = app.state.physics_section
        assert section["anchor"] == lesson.reference.split("#")[1]
        assert section["title"] and len(section["html"]) > 200
    app.logic.physics.close()
    assert app.state.physics_section is None
    for bad in ("docs/physics.md#no-such-section", "../../etc/passwd", 7, None):
        app.state.input_message = ""
        app.logic.physics.open(bad)
        assert app.state.physics_section is None
        assert app.state.input_message == "Physics page: no such section"


def test_a_background_too_small_to_see_beside_the_echo_gets_its_own_axis(app):
    change(app, sun_mode="manual", sun_elevation_deg=90.0, filter_width_nm=100.0)
    change(app, pulse_energy_mj=5.0, tnr=5.0)
    result = app.logic.last_frame.result
    power = result.background.power_w
    row, col = (int(i) for i in np.unravel_index(np.argmax(power), power.shape))
    app.logic.on_pixel_click(row, col)
    figure = app.state.waveforms
    traces = {t["name"].split(" ")[0]: t for t in figure["data"]}
    level, band = traces["background"], traces["noise"]
    echo_peak = max(
        max(t["y"])
        for t in figure["data"]
        if t.get("mode") == "lines"
        and "x" in t
        and t.get("yaxis") is None
        and t["y"]
        and t["y"][0] is not None
    )
    assert level["yaxis"] == band["yaxis"] == "y2" and "right axis" in level["name"]
    assert "right axis" in figure["layout"]["yaxis2"]["title"]["text"]
    # on its own axis the level is a readable number of its unit, not a sliver of the echo's
    assert 1.0 <= max(level["y"]) < 1000.0 and echo_peak > 0
    change(app, sun_mode="none")


def test_every_lessons_read_more_is_written_for_readers_with_its_maths_drawn(app, monkeypatch):
    from app.logic.lessons import LESSONS
    from app.logic.physics_page import DOCS_URL_ENV

    monkeypatch.delenv(DOCS_URL_ENV, raising=False)
    for lesson in LESSONS:
        app.logic.physics.read_more(lesson.key)
        shown = app.state.physics_section
        assert shown["kind"] == "reader" and shown["title"] == lesson.reference_title
        page = shown["html"]
        assert page.count("<math") >= 1, lesson.key  # an equation, drawn
        for raw in ("$", "\\frac", "\\text", "tests/", "simcore", ".py", "::", "docs/"):
            assert raw not in page, (lesson.key, raw)
        # the way to the full derivation: the physics page's own section, in the dialog
        assert shown["docs_url"] == "" and shown["full"] is True
        app.logic.physics.open(shown["anchor"])
        full = app.state.physics_section
        assert full["kind"] == "physics" and full["anchor"] == shown["anchor"]
        assert "$" not in full["html"] and len(full["html"]) > 200
    monkeypatch.setenv(DOCS_URL_ENV, "https://docs.example.org/lmapd/")
    app.logic.physics.read_more("double-peak")
    assert app.state.physics_section["docs_url"] == "https://docs.example.org/lmapd/physics/#eq-29"
    for bad in ("no-such-lesson", 7, None, ["double-peak"]):
        app.state.physics_section = None
        app.logic.physics.read_more(bad)
        assert app.state.physics_section is None
        assert app.state.input_message == "Read more: no such lesson"


def test_maths_the_markdown_holds_becomes_mathml_and_the_rest_stays_text():
    from app.logic.physics_page import markdown_html

    page = markdown_html(
        "Rice's rate $\\nu_0\\,e^{-\\mathrm{TNR}^2/2}$ costs $5 or $6.\n\n$$t = \\frac{2r}{c}$$"
    )
    assert page.count("<math") == 2 and 'display="block"' in page and "<mfrac>" in page
    assert "costs $5 or $6." in page  # a price is no formula: "$5 or $" has a space inside


def test_a_refusal_writes_its_figure_and_its_limit_alike():
    from app.engine import about

    assert about(8e6) == about(7_990_000.0) == "8,000,000"
    assert about(12_345_678.0) == "12,000,000" and about(0.5) == "0.5" and about(96.0) == "96"


def test_the_stats_give_the_range_error_beside_its_sigma_and_the_background_where_it_lights(app):
    # the orbit's Sun at its epoch: the target mostly in shade, a few pixels lit (the median
    # over every pixel with an echo is 0 W)
    change(app, sun_mode="orbit", tnr=5.0)
    result = app.logic.last_frame.result
    d = result.detection
    error_m = np.abs(d.range_m - d.range_true_m)[d.detected]
    labels = [row["label"] for row in app.state.stats]
    at = labels.index("Median range σ")
    assert labels[at + 1] == "Median range error (against the noise-free range)"
    assert stat(app, labels[at + 1]) == f"{np.median(error_m) * 100:.3g} cm"
    power = result.background.power_w.ravel()
    lit = power[power > 0]
    assert 0 < len(lit) < len(power)
    shown = stat(app, "Median background power (pixels in light)")
    from app.payloads.encode import si_text

    assert shown == si_text(float(np.median(lit)), "W") and not shown.startswith("0 ")
    assert stat(app, "Pixels in background light").startswith(f"{len(lit):,d} of {len(power):,d}")
    assert "Median background power" not in labels  # one figure, named for what it is
    change(app, sun_mode="none")


def test_every_glossary_word_on_a_card_links_to_its_entry():
    import html
    import re

    from app.logic.lessons import LESSONS
    from app.logic.words import CARD_WORDS

    assert set(CARD_WORDS) <= set(GLOSSARY)
    # the words the classroom found unexplained on the cards
    for word in ("shot noise", "Rice's rate", "BRDF", "AC-coupled", "Coates' correction"):
        assert any(word in forms for forms in CARD_WORDS.values()), word
    assert "photoelectron" in CARD_WORDS["Photoelectron"] and "σ" in CARD_WORDS["σ (sigma)"]
    link = re.compile(r'<a href="#glossary" class="glossary-link" data-term="([^"]+)">.*?</a>')
    used = set()
    for lesson in LESSONS:
        card = lesson.card()
        for name in ("basic", "look", "why", "try_next"):
            page = card[f"{name}_html"]
            assert html.unescape(re.sub(r"<[^>]+>", "", page)) == card[name]  # the same text
            linked = {html.unescape(t) for t in link.findall(page)}
            used |= linked
            rest = html.unescape(link.sub(" ", page))  # the words left unlinked
            for term, forms in CARD_WORDS.items():
                for form in forms:
                    found = re.search(rf"(?<![\w'-]){re.escape(form)}(?![\w-])", rest, re.I)
                    assert found is None or term in linked, (lesson.key, name, form)
    for word in ("Shot noise", "Rice's rate", "AC-coupled", "Coates' correction", "σ (sigma)"):
        assert word in used, word  # each is on a card, and linked there
    assert "Photoelectron" in used


def test_the_stats_rows_have_glossary_entries(app):
    change(app, pulse_energy_mj=5.0, tnr=5.0, sun_mode="none")
    terms = {row["label"]: row.get("term") for row in app.state.stats}
    assert terms["Points"] == "Point cloud" and terms["Median range σ"] == "σ (sigma)"
    assert terms["Taken by a false alarm (its stop used)"] == "Stop"
    assert all(term in GLOSSARY for term in terms.values() if term)
    assert sum(1 for term in terms.values() if term) >= len(terms) - 2


def test_the_teachers_guide_covers_every_lesson_and_the_glossary_links_it(monkeypatch):
    from pathlib import Path

    from app.logic.lessons import LESSONS
    from app.logic.physics_page import DOCS_URL_ENV, docs_url

    guide = (Path(__file__).resolve().parents[2] / "docs" / "teaching.md").read_text()
    for lesson in LESSONS:  # each lesson: its link's key, goal, questions, mistakes, time
        at = guide.index(f"(`{lesson.key}`)")
        section = guide[at : guide.find("\n### ", at) if "\n### " in guide[at:] else None]
        for part in ("Learning goal", "Questions to ask", "What students get wrong", "Time"):
            assert f"**{part}:**" in section, (lesson.key, part)
    assert "?lesson=double-peak" in guide
    monkeypatch.setenv(DOCS_URL_ENV, "https://docs.example.org/lmapd")
    assert docs_url("", "teaching") == "https://docs.example.org/lmapd/teaching/"
    monkeypatch.setenv(DOCS_URL_ENV, "javascript:alert(1)")
    assert docs_url("eq-29") == ""  # only a web address
