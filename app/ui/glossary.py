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
    # the words of the lessons' cards, for a reader of 14-16 (every one a card uses links here)
    "Lidar": "Light detection and ranging: a laser sends a short flash and a timer measures how "
    "long its light takes to come back, which gives the distance.",
    "Echo": "The light of the laser flash that a surface sends back, as a pixel records it over "
    "time (on the waveform chart).",
    "Threshold": "The level a pixel's signal must cross for the pixel to decide that an echo "
    "has arrived and give a point (dash-dot on the waveform chart).",
    "Noise": "The random wobble of a signal that is there even with no light at all: it comes "
    "from the detector, its electronics and the light itself.",
    "σ (sigma)": "The typical size of a random wobble (its standard deviation): about two "
    "thirds of the time the noise is within ±σ.",
    "Shot noise": "Light arrives as separate photons at random moments, so even steady light "
    "flickers; the more light, the larger the flicker (it grows as the square root of the "
    "light).",
    "Rice's rate": "How often noise alone crosses a threshold upwards, per second. It falls "
    "very fast as the threshold rises, as exp(−TNR²/2) (worked out by S. O. Rice in 1944).",
    "False alarm": "Noise alone crossing the threshold: the pixel gives a point where there is "
    "nothing (an outlier, red in the point cloud).",
    "Stop": "The pixel's timer stops at the first crossing of the threshold: it records one "
    "time per flash (one stop), so a false alarm before the echo takes the echo's place.",
    "Range gate": "The stretch of distances in which the pixels listen for echoes after each "
    "flash.",
    "BRDF": "Bidirectional reflectance distribution function: how much light a material sends "
    "back in each direction; for a lidar, how bright a surface looks at each angle.",
    "Reflectance": "How much of the light falling on a surface it sends back towards the lidar "
    "(per unit of solid angle, in 1/sr).",
    "Specular": "Mirror-like reflection: strong in one direction only (a shiny surface).",
    "Diffuse": "Matte reflection, as from paper: the light goes out in every direction.",
    "Normal": "The direction straight out of a surface; the angle from it says how tilted the "
    "surface is seen.",
    "Grazing incidence": "Seeing a surface almost edge-on, close to 90° from its normal: it "
    "shows almost no area and sends almost nothing back.",
    "AC-coupled": "An electronic input that passes changes and blocks a steady level: the "
    "steady background is removed, but its flicker (shot noise) stays.",
    "Photon": "A single particle of light. A laser flash of 1 mJ at 1064 nm holds about 5 × "
    "10¹⁵ of them.",
    "Photoelectron": "An electron freed by one photon in the detector: the detector counts the "
    "light it catches in photoelectrons.",
    "Coates' correction": "A correction of Geiger-mode counts: each pulse records only its "
    "earliest photon, so later time bins are under-counted; Coates (1968) showed how to undo "
    "this from the counts themselves.",
    "Geiger mode": "A detector so sensitive that a single photon sets off an avalanche of "
    "current; it counts photons over many pulses.",
    "Linear mode": "A detector whose output grows in proportion to the light: it measures the "
    "echo's strength in one flash.",
    "Histogram": "A bar chart of counts: here, how many photons arrived in each short time bin.",
    "Field of view": "The angle the camera sees, shared by its pixels.",
    "Fly-around": "The lidar's orbit carries it around the target: a picture every few minutes, "
    "each from a new side.",
    "Point cloud": "The 3D points the lidar measured: at most one per pixel per flash.",
    "Median": "The middle value: half of the values are above it, half below.",
    "Band-limited": "The electronics cannot follow very fast changes, so the recorded pulse is "
    "a little smoothed and widened.",
    "Irradiance": "The light power falling on each square metre [W/m²].",
    "Solid angle": "How large something looks from a point, as the area it covers on a sphere "
    "of radius 1 around that point [sr, steradian].",
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


def js_text(text: str) -> str:
    """``text`` as a JavaScript string in single quotes, for an expression in one of the page's
    attributes (which are in double quotes): "Rice's rate" -> 'Rice\\'s rate'."""
    escaped = text.replace("\\", "\\\\").replace("'", "\\'").replace('"', "\\x22")
    return f"'{escaped}'"


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
                click=f"glossary_term = {js_text(CONTROL_TERMS[key][0])}; glossary_open = true",
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
                with html.P(classes="text-caption mb-2 teaching-guide"):
                    html.Span("For teachers: ")
                    html.A(
                        "the teacher's guide",
                        v_if="teaching_url",
                        href=("teaching_url",),
                        target="_blank",
                        rel="noopener",
                    )
                    html.Span("the teacher's guide (docs/teaching.md)", v_else=True)
                    html.Span(
                        " gives each lesson's learning goal, questions to ask, what students "
                        "get wrong and how long it takes, and how to run a class with one link "
                        "per lesson."
                    )
                with html.Dl(classes="glossary-list"):
                    for term, text in GLOSSARY.items():
                        quoted = js_text(term)
                        with html.Div(
                            classes=(
                                f"['glossary-entry', glossary_term === {quoted} ? "
                                "'glossary-asked' : '']",
                            ),
                            style=(f"{{ order: glossary_term === {quoted} ? -1 : 0 }}",),
                        ):
                            html.Dt(term, classes="glossary-term")
                            html.Dd(text, classes="glossary-text")
