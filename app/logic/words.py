"""The words of the lessons' cards that the glossary explains, a child of the app's logic: each
glossary term a card may use with the forms it takes, and a card's text as HTML with the first
use of each linked to its entry (the page opens the glossary there: app.ui.lessons; the entries
themselves are app.ui.glossary's, and a test checks that every term here has one)."""

from __future__ import annotations

import html
import re
from functools import lru_cache

# Each glossary term a card may use, and the forms it takes in a card's text (matched whole
# words, any case): a card's text links the first of each to its entry
CARD_WORDS: dict[str, tuple[str, ...]] = {
    "Lidar": ("lidar",),
    "Echo": ("echo", "echoes"),
    "Threshold": ("threshold",),
    "Shot noise": ("shot noise",),
    "Noise": ("noise",),
    "σ (sigma)": ("σ", "sigma"),
    "Rice's rate": ("Rice's rate",),
    "False alarm": ("false alarm", "false alarms"),
    "Outlier": ("outlier", "outliers"),
    "Stop": ("stop", "stops"),
    "Range gate": ("range gate",),
    "Range": ("range",),
    "BRDF": ("BRDF",),
    "Reflectance": ("reflectance", "reflects"),
    "Specular": ("specular",),
    "Diffuse": ("diffuse",),
    "Normal": ("normal",),
    "Grazing incidence": ("grazing incidence",),
    "AC-coupled": ("AC-coupled",),
    "Photoelectron": ("photoelectron", "photoelectrons"),
    "Photon": ("photon", "photons"),
    "Coates' correction": ("Coates' correction",),
    "Geiger mode": ("Geiger-mode", "Geiger mode"),
    "Linear mode": ("linear-mode", "linear mode"),
    "Histogram": ("histogram",),
    "Field of view": ("field of view",),
    "Fly-around": ("fly-around",),
    "Point cloud": ("point cloud",),
    "Median": ("median",),
    "Band-limited": ("band-limited",),
    "Irradiance": ("irradiance",),
    "Solid angle": ("solid angle",),
    "TNR": ("TNR",),
    "SNR": ("SNR",),
    "P_d": ("P_d",),
    "Pixel": ("pixel", "pixels"),
    "Pulse energy": ("pulse energy",),
    "Background light": ("background light", "background"),
    "Filter width": ("filter width", "filter"),
    "Dead time": ("dead time", "dead"),
    "Dark count": ("dark count",),
    "Pulses per frame": ("pulses per frame",),
    "Pose": ("pitch", "azimuth"),
    "Half-maximum time": ("half maximum",),
}


@lru_cache(maxsize=1)
def _card_pattern() -> re.Pattern[str]:
    forms = sorted(
        ((form, term) for term, all_forms in CARD_WORDS.items() for form in all_forms),
        key=lambda pair: -len(pair[0]),  # the longest first: "shot noise" before "noise"
    )
    alternatives = "|".join(rf"(?:{re.escape(form)})" for form, _ in forms)
    return re.compile(rf"(?<![\w'-])(?:{alternatives})(?![\w-])", re.IGNORECASE)


def card_term(word: str) -> str:
    """The glossary term of a word a card uses (one of ``CARD_WORDS``' forms, any case)."""
    low = word.lower()
    return next(t for t, forms in CARD_WORDS.items() if low in (f.lower() for f in forms))


def linked_parts(text: str) -> list[tuple[str, str]]:
    """``text`` cut into (words, glossary term or "") parts: the first use of each glossary
    term a card may use is its own part, linked to its entry; the rest stays as it is."""
    parts: list[tuple[str, str]] = []
    seen: set[str] = set()
    at = 0
    for m in _card_pattern().finditer(text):
        term = card_term(m.group(0))
        if term in seen:
            continue
        seen.add(term)
        if m.start() > at:
            parts.append((text[at : m.start()], ""))
        parts.append((m.group(0), term))
        at = m.end()
    if at < len(text):
        parts.append((text[at:], ""))
    return parts


def linked_html(text: str) -> str:
    """``text`` as HTML, its glossary words linked (:func:`linked_parts`): ``<a
    class="glossary-link" data-term="TERM">``, everything escaped."""
    out = []
    for words, term in linked_parts(text):
        shown = html.escape(words)
        if term:
            out.append(
                f'<a href="#glossary" class="glossary-link" '
                f'data-term="{html.escape(term, quote=True)}">{shown}</a>'
            )
        else:
            out.append(shown)
    return "".join(out)
