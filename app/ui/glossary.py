"""The words of the page explained: a glossary (TNR, SNR, P_d, FWHM, CFD, pile-up, ...) with an
info button beside every control that opens the entries it needs, and the whole glossary in a
dialog from the app bar."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import Any

from trame.widgets import html
from trame.widgets import vuetify3 as v3

from app.state import receiver_controls
from app.ui.widgets import html_attributes
from simcore import receivers

# term -> what it means here, in a sentence or two a student can read at the slider: the words
# of every receiver (a receiver's own, and its half of a shared word, are in its declaration)
_GENERAL_GLOSSARY: dict[str, str] = {
    "TNR": "Threshold-to-noise ratio: the detection threshold as a multiple of the noise's "
    "standard deviation σn. A pixel gives a point when its signal crosses TNR × σn: a higher "
    "TNR means fewer false alarms and more missed echoes.",
    "SNR": "Signal-to-noise ratio:",
    "P_d": "Probability of detection: the chance that a pixel's echo crosses the threshold in "
    "this flash. An echo with P_d 0.90 is still missed one flash in ten, by chance (the noise "
    "pulled it under the threshold); the seed decides which.",
    "FWHM": "Full width at half maximum: a pulse's duration between the two times it is at half "
    "of its peak power.",
    "Outlier": "A false alarm: a point from noise crossing the threshold where there is no echo "
    "(red in the point cloud).",
    "Range": "The distance along a pixel's line of sight, c t / 2 from the echo's time t since "
    "the pulse left.",
    "Pose": "The target's attitude seen from the lidar: pitch and azimuth turn it, the distance "
    "moves it along the line of sight.",
    "Pixel": "One detector element of the square array: it sees a small cone of the field of "
    "view and gives at most one point (a mixed pixel sees two surfaces).",
    "Pulse energy": "The laser energy of one flash: the received power and the SNR scale with it.",
    "Background light": "Sunlight scattered by the target and the Earth into the receiver:",
    "Filter width": "The band-pass filter in front of the detector: a narrower filter lets in "
    "less background light.",
    "Seed": "The number the random draws start from: the same seed gives the same noise, the "
    "same points.",
    "Fidelity": "How finely the rays sample each pixel (sub-rays) and how the noise is modelled: "
    "finer is truer and slower.",
}

# each control's entries, first the one it sets
_SHARED_TERMS: dict[str, tuple[str, ...]] = {
    "pitch_deg": ("Pose",),
    "azimuth_deg": ("Pose",),
    "distance_m": ("Range", "Pose"),
    "pixels": ("Pixel",),
    "pulse_energy_mj": ("Pulse energy", "SNR"),
    "tnr": ("TNR", "SNR", "P_d"),
    "seed": ("Seed", "P_d"),
    "sun_azimuth_deg": ("Background light",),
    "sun_elevation_deg": ("Background light",),
    "filter_width_nm": ("Filter width", "Background light"),
    "receiver_kind": ("SNR", "Pile-up"),
    "sun_mode": ("Background light",),
    "preset": ("Fidelity",),
    "color_by": ("Range", "SNR", "Outlier"),
}


class _Merged(Mapping[str, Any]):
    """A dict of the page's own entries and those the known receivers declare (read at each
    use: a receiver registered before the app starts is in)."""

    def __init__(self, build: Callable[[], dict[str, Any]]):
        self._build = build

    def __getitem__(self, key: str) -> Any:
        return self._build()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._build())

    def __len__(self) -> int:
        return len(self._build())


def merged_glossary() -> dict[str, str]:
    """Term -> its explanation: the page's general entries, then each known receiver's (its
    declaration's ``glossary``, in the registry's order). A term new to the glossary is a new
    entry; a term already there gets the receiver's text after the entry's, one space between:
    the receiver's half of a shared word ("SNR": the page's lead, the linear mode's meaning,
    then the Geiger mode's)."""
    merged = dict(_GENERAL_GLOSSARY)
    for receiver in receivers.receivers():
        for term, text in receiver.glossary:
            merged[term] = f"{merged[term]} {text}" if term in merged else text
    return merged


# term -> its explanation (:func:`merged_glossary`)
GLOSSARY: Mapping[str, str] = _Merged(merged_glossary)
# control -> its terms: the page's, then the receivers' controls' (the terms they name)
CONTROL_TERMS: Mapping[str, tuple[str, ...]] = _Merged(
    lambda: {
        **_SHARED_TERMS,
        **{name: c.terms for name, c in receiver_controls().items() if c.terms},
    }
)


def control_text(key: str) -> str:
    """The glossary entries of control ``key``, one paragraph each."""
    return "\n\n".join(f"{term}: {GLOSSARY[term]}" for term in CONTROL_TERMS[key])


def info_button(key: str, name: str) -> None:
    """A small info button beside control ``key`` (``name``: its label): its glossary entries
    in a tooltip on hover or keyboard focus; a click opens the glossary at its first term. None
    for a control without entries (a receiver's that names no term)."""
    if key not in CONTROL_TERMS:
        return
    with v3.VTooltip(location="top", max_width=360, open_on_focus=True):
        with v3.Template(v_slot_activator="{ props }"):
            v3.VBtn(
                icon="mdi-information-outline",
                v_bind="props",
                size="x-small",
                density="compact",
                variant="text",
                color="primary",
                click=f"glossary_term = '{CONTROL_TERMS[key][0]}'; glossary_open = true",
                classes=f"info-button info-{key}",
                **html_attributes(aria_label=f"What is {name}?"),
            )
        for i, term in enumerate(CONTROL_TERMS[key]):
            with html.Div(classes="glossary-tip" + (" mt-2" if i else "")):
                html.B(f"{term}: ")
                html.Span(GLOSSARY[term])


def glossary_button() -> None:
    """The app bar's button that opens the glossary."""
    v3.VBtn(
        icon="mdi-book-alphabet",
        color="white",
        variant="text",
        size="small",
        click="glossary_term = ''; glossary_open = true",
        title="Glossary: the words of the page",
        classes="glossary-button",
        **html_attributes(aria_label="Glossary"),
    )


def glossary_dialog() -> None:
    """Every entry, the one asked for first and marked."""
    with v3.VDialog(v_model=("glossary_open", False), max_width=640, scrollable=True):
        with v3.VCard(classes="glossary-card", **html_attributes(aria_label="Glossary")):
            with v3.VCardTitle(classes="card-title d-flex align-center"):
                html.Span("Glossary")
                v3.VSpacer()
                v3.VBtn(
                    icon="mdi-close",
                    size="small",
                    variant="text",
                    click="glossary_open = false",
                    **html_attributes(aria_label="Close the glossary"),
                )
            with v3.VCardText():
                with html.Dl(classes="glossary-list"):
                    for term, text in GLOSSARY.items():
                        with html.Div(
                            classes=(
                                f"['glossary-entry', glossary_term === '{term}' ? "
                                "'glossary-asked' : '']",
                            ),
                            style=(f"{{ order: glossary_term === '{term}' ? -1 : 0 }}",),
                        ):
                            html.Dt(term, classes="glossary-term")
                            html.Dd(text, classes="glossary-text")
