"""Shared links in a real Chromium: a link with settings opens on that scene (the same points as
the core gives for them), the page's own link reproduces it, and a tampered link shows a message
and the defaults, never an error page."""

from __future__ import annotations

import urllib.parse

import pytest
from support.launch import JS_STATE, wait_first_frame, wait_settled

import simcore

pytestmark = pytest.mark.browser


def state(page, name: str):
    return page.evaluate(JS_STATE, name)


def point_count(page) -> int:
    return int(page.locator(".point-count").inner_text().split()[0].replace(",", ""))


def open_link(page, app_url: str, settings: dict[str, str]) -> None:
    page.goto(app_url + "&" + urllib.parse.urlencode(settings))
    wait_first_frame(page)
    page.wait_for_function(
        "(p) => window.trame.state.get('pixels') === p", arg=int(settings.get("pixels", 256))
    )
    wait_settled(page)


def test_a_link_opens_its_scene_and_the_pages_link_reproduces_it(page, app_url):
    settings = {
        "pitch_deg": "30",
        "azimuth_deg": "-20",
        "pixels": "64",
        "seed": "3",
        "pulse_energy_j": "0.002",
        "preset": "interactive",
    }
    open_link(page, app_url, settings)
    assert (state(page, "pitch_deg"), state(page, "azimuth_deg")) == (30, -20)
    assert state(page, "pulse_energy_mj") == 2 and state(page, "input_message") == ""
    typed = {k: v if k == "preset" else float(v) for k, v in settings.items()}
    typed.update(pixels=64, seed=3)
    expected = simcore.simulate(overrides=typed)
    assert point_count(page) == expected.summary()["n_points"]
    page.get_by_role("button", name="Share this scene (link)").click()
    link = page.locator(".share-link input").input_value()
    shared = dict(urllib.parse.parse_qsl(urllib.parse.urlsplit(link).query))
    assert shared["token"] and shared["pitch_deg"] == "30" and shared["pixels"] == "64"
    assert shared["pulse_energy_j"] == "0.002"
    # only what differs from the start (the preset is the initial one)
    assert set(shared) == {"token", *settings} - {"preset"}


def test_a_tampered_link_falls_back_with_a_message_and_no_error_page(page, app_url):
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    open_link(page, app_url, {"pitch_deg": "abc", "pixels": "48", "<script>": "alert(1)"})
    message = page.locator(".input-message").inner_text()
    assert "Pitch: 'abc' is not a number" in message and "unknown setting '<script>'" in message
    assert state(page, "pitch_deg") == 0 and point_count(page) > 0 and errors == []
    page.goto(app_url + "&pixels=256")  # back to the paper scene for the other tests
    wait_first_frame(page)
    wait_settled(page)
