"""The page's own scripts and styles: the files of ``app/static/``, served through trame's module
mechanism (``Server.enable_module``: a folder served under a name, the scripts and style sheets
the page loads from it).

The page loads them after it connected and before it mounts (trame's client), the style sheets
after those of the widget libraries enabled before (:func:`enable` is called last, once the
layout is built: its rules win over the libraries' ones of the same weight), the scripts all
requested at once (each stands alone: none needs another to have run). The folder is served
under a name with a digest of the files' contents, so a browser never keeps an old copy of one
after an update. ``make lint`` parses the scripts (``node --check``).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

STATIC_DIR = Path(__file__).resolve().parent.parent / "static"
SCRIPTS = (
    "frame.js",  # frame pacing: trame.utils.lmapd.frameShown (app.ui.layout.FRAME_SHOWN)
    "binary.js",  # binary arrays as typed arrays: trame.utils.lmapdBin (app.ui.views3d)
    "a11y.js",  # accessible names and spoken values of the controls
    "link.js",  # shared links: trame.utils.lmapdLink (app.ui.controls), the address bar
    "view-scroll.js",  # the 3D views leave the page's scroll alone
    "cursor.js",  # the waveform chart's measuring cursor: trame.utils.lmapdCursor (app.ui.panels)
    "keyboard.js",  # log sliders' keys, the array image's cursor pixel, Copy link's answer
    "lesson.js",  # an opened lesson brings its view into sight: trame.utils.lmapdLesson
    "charts.js",  # the charts' library after the first frame: trame.utils.lmapdCharts (charts)
    "lit.js",  # the 3D scene's lit side, the facets' colours: trame.utils.lmapdLit (views3d)
)
STYLES = ("page.css", "markers.css", "glossary.css", "lessons.css")


def served_name(folder: Path = STATIC_DIR) -> str:
    """The name the folder is served under: ``__lmapd_`` and 12 hex digits of the sha256 of its
    files (names and contents)."""
    digest = hashlib.sha256()
    for name in (*SCRIPTS, *STYLES):
        digest.update(name.encode() + b"\0" + (folder / name).read_bytes() + b"\0")
    return f"__lmapd_{digest.hexdigest()[:12]}"


def module(folder: Path = STATIC_DIR) -> dict[str, object]:
    """The trame module of the page's files (for ``Server.enable_module``)."""
    name = served_name(folder)
    return {
        "serve": {name: str(folder)},
        "scripts": [f"{name}/{file}" for file in SCRIPTS],
        "styles": [f"{name}/{file}" for file in STYLES],
    }


def enable(server) -> None:
    """Serve the page's files on ``server`` and have its page load them."""
    server.enable_module(module())
