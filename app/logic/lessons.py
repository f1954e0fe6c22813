"""Lessons: one-click scenes that teach, each with a card saying what to look at and why, a child
of the app's logic.

A lesson is a data record, one TOML file per lesson in ``assets/lessons/`` (shipped inside the
package as ``simcore.assets.lessons``, read by :func:`load_lessons`): its scene as the settings of a
shared link (the names of ``lmapd simulate --set``, in SI units, read by
``app.logic.links.controls_from_link``), the display choices, the mode (single frame or a fly-around
frame), the pixels to select, and a short card: what to look at, the physics behind it, what to try
next, and the section of docs/physics.md that explains it. Every number on a card is a named figure
of the record, and tests/app/test_app_lessons.py computes each one again from the simulation: the
card's text rendered from the computed figures must equal the text rendered from the record's.

The lessons are written for the paper scene (the MRO at 500 m, ``lmapd simulate`` with no
options): a lesson starts from the app's initial controls and sets every control it depends on
(``PAPER_SETTINGS`` and its own), so it gives the same frame whatever the user changed before.
With another target (the drop-down, an upload, ``--scene``) a lesson still sets its controls, and
its card says that its figures are the MRO's.

A lesson starts clean: the views it does not name go to a stated state. The controls and the
colour modes (``color_by``, ``image_kind``: the record's, default the range), the mode, the
selection (the record's pixels only), no pinned frame and no highlighted part (the server); the
array image showing the whole array, or zoomed to the selected pixels where the card is about
the array image (``card()["zoom"]``), the 3D views at their home cameras, the waveform cursor
cleared, no outline of an earlier lesson (the page: app/static/lesson.js). A lesson's link,
``?lesson=KEY``, opens it so.

The parent (``AppLogic``) registers the page's ``open_lesson`` and ``leave_lesson`` triggers and
calls :meth:`LessonGuide.plan` (what a lesson sets), :meth:`LessonGuide.opened` (the card on the
page) and :meth:`LessonGuide.leave`. Leaving only hides the card: the scene stays as it is.
"""

from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from app.logic.links import controls_from_link
from app.logic.words import linked_html
from app.state import MAX_SELECTED_PIXELS, Controls, echo
from simcore._assets import ASSETS_DIR

MJ = 1e-3  # J per mJ: a pulse energy written as ``0.1 * MJ`` shows as 0.1 mJ on the slider
NM = 1e-9  # m per nm: a filter width written as ``100 * NM`` shows as 100 nm
LESSONS_DIR = ASSETS_DIR / "lessons"  # the built-in lessons: NN-KEY.toml, in their order
LESSON_TARGET = "Mars Reconnaissance Orbiter"  # the target whose figures the cards give
# the views a card can point at: its name on the card, and the page's element (app.ui)
VIEWS: dict[str, tuple[str, str]] = {
    "waveform": ("the waveform chart", ".waveform-card"),
    "array": ("the detector array image", ".array-card"),
    "cloud": ("the point cloud", ".cloud-card"),
    "scene": ("the 3D scene", ".scene-card"),
    "stats": ("the statistics", ".stats-card"),
    "attitudes": ("the attitude map", ".attitudes-card"),
}

# The paper scene's controls as link settings (its pose, array, pulse, threshold, seed, fidelity,
# no Sun, the linear-mode receiver): every lesson starts from these, so the same lesson gives the
# same frame whatever was set before (the Geiger-mode parameters and the materials: the initial).
PAPER_SETTINGS: dict[str, Any] = {
    "pitch_deg": 0.0,
    "azimuth_deg": 0.0,
    "distance_m": 500.0,
    "pixels": 256,
    "pulse_energy_j": 5 * MJ,
    "tnr": 5.0,
    "seed": 0,
    "preset": "interactive",
    "sun.mode": "none",
    "sun.azimuth_deg": 0.0,
    "sun.elevation_deg": 30.0,
    "receive.filter_width_m": 1 * NM,
    "receiver.kind": "lm_apd",
}


@dataclass(frozen=True)
class Lesson:
    """One lesson.

    key : its name in the page's ``open_lesson`` trigger (lowercase, hyphens)
    title : the button's and the card's title
    settings : the scene's link settings that differ from ``PAPER_SETTINGS`` (SI units)
    selection : the pixels to select, (row, col) on the lesson's array
    basic : the card's text for a reader of 14-16, a template of ``figures`` as the others
    look, why, try_next : the card's three paragraphs of "More detail", ``str.format``
        templates of ``figures`` (a template holds no digit of its own: every number on the
        card is a figure)
    reference : the section that explains it: ``docs/physics.md``, ``#``, one of its anchors
    reference_title : that section's title
    read_more : the "Read more" text for the app's readers, Markdown with ``$...$`` maths (what
        the equation says in words, then the equation; app.logic.physics_page draws it)
    figures : the card's numbers, each computed again by the tests
    color_by, image_kind : the display choices (``app.state.COLOR_BY``, ``IMAGE_KINDS``)
    mode, fly_t_s, fly_j2 : single frame, or the fly-around frame at ``fly_t_s`` [s]
    view : the view its card is about (a key of ``VIEWS``): the page brings it into sight
    attitudes : whether opening it computes the attitude map (app.logic.attitudes)
    """

    key: str
    title: str
    settings: Mapping[str, Any]
    selection: tuple[tuple[int, int], ...]
    look: str
    why: str
    try_next: str
    reference: str
    reference_title: str
    basic: str = ""
    read_more: str = ""
    figures: Mapping[str, float] = field(default_factory=dict)
    color_by: str = "range"
    image_kind: str = "range"
    mode: str = "single"
    fly_t_s: float = 0.0
    fly_j2: bool = False
    view: str = "waveform"
    attitudes: bool = False

    @property
    def link_settings(self) -> dict[str, Any]:
        """Every control of the lesson's scene as link settings (SI units)."""
        return {**PAPER_SETTINGS, **self.settings}

    def card(self, figures: Mapping[str, float] | None = None) -> dict[str, str]:
        """The card's text, with ``figures`` (default: the record's) in its templates."""
        values = self.figures if figures is None else figures
        texts = {
            name: getattr(self, name).format_map(values)
            for name in ("basic", "look", "why", "try_next")
        }
        return {
            "key": self.key,
            "title": self.title,
            **texts,
            # the same, their glossary words linked (app.logic.words)
            **{f"{name}_html": linked_html(text) for name, text in texts.items()},
            "reference": self.reference,
            "reference_title": self.reference_title,
            "note": "",
            "view": VIEWS[self.view][0],
            "view_selector": VIEWS[self.view][1],
            # the array image: zoomed to the lesson's pixels where the card is about it, else
            # the whole array (app/static/lesson.js)
            "zoom": "pixels" if self.view == "array" else "whole",
        }


class LessonError(ValueError):
    """A lesson file that cannot be read: the file and the key are named."""


LESSON_FIELDS = tuple(f.name for f in dataclasses.fields(Lesson))
TEXT_FIELDS = ("look", "why", "try_next", "basic", "key", "title", "reference", "view", "read_more")
REQUIRED_FIELDS = tuple(
    f.name
    for f in dataclasses.fields(Lesson)
    if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
)


def lesson_from_record(record: Mapping[str, Any], source: str = "a lesson") -> Lesson:
    """A :class:`Lesson` of one lesson file's table (``source``: the file, named in errors).

    Raises LessonError for a missing or unknown key or a value of the wrong type."""
    unknown = sorted(set(record) - set(LESSON_FIELDS))
    missing = sorted(name for name in REQUIRED_FIELDS if name not in record)
    if unknown or missing:
        said = [f"unknown key {', '.join(unknown)}"] if unknown else []
        said += [f"missing key {', '.join(missing)}"] if missing else []
        raise LessonError(f"{source}: {'; '.join(said)}")
    values = dict(record)
    try:
        values["selection"] = tuple((int(r), int(c)) for r, c in record["selection"])
        for name in ("settings", "figures"):
            if not isinstance(values.get(name, {}), Mapping):
                raise TypeError(f"{name} is not a table")
        for name in TEXT_FIELDS:
            if not isinstance(values.get(name, ""), str):
                raise TypeError(f"{name} is not a string")
        figures = values.get("figures", {})
        odd = [
            k for k, v in figures.items() if isinstance(v, bool) or not isinstance(v, int | float)
        ]
        if odd:
            raise TypeError(f"figure {', '.join(odd)} is not a number")
    except (TypeError, ValueError) as exc:
        raise LessonError(f"{source}: {exc}") from None
    if values.get("view", "waveform") not in VIEWS:
        raise LessonError(f"{source}: view {values['view']!r} is none of {', '.join(VIEWS)}")
    lesson = Lesson(**values)
    try:
        lesson.card()  # every figure its card names, in the format it gives
    except KeyError as exc:
        raise LessonError(f"{source}: its card names the figure {exc.args[0]}, not given") from None
    except (ValueError, IndexError) as exc:
        raise LessonError(f"{source}: its card cannot be written: {exc}") from None
    return lesson


def load_lessons(folder: Path | None = None) -> tuple[Lesson, ...]:
    """The lessons of ``folder`` (default: the built-in ones, ``assets/lessons``), one per
    ``NN-KEY.toml`` file, in the order of their file names; each file's ``key`` is the name
    after its number."""
    folder = LESSONS_DIR if folder is None else folder
    lessons = []
    for path in sorted(folder.glob("*.toml")):
        with path.open("rb") as file:
            try:
                record = tomllib.load(file)
            except tomllib.TOMLDecodeError as exc:
                raise LessonError(f"{path.name}: {exc}") from None
        lesson = lesson_from_record(record, path.name)
        if path.stem.partition("-")[2] != lesson.key:
            raise LessonError(f"{path.name}: its key is {lesson.key!r}, not the file's name")
        lessons.append(lesson)
    return tuple(lessons)


LESSONS: tuple[Lesson, ...] = load_lessons()

BY_KEY: dict[str, Lesson] = {lesson.key: lesson for lesson in LESSONS}


@dataclass(frozen=True)
class LessonPlan:
    """What opening a lesson sets: the controls, the mode's state, the pixels to select and any
    message (a setting the controls had to change)."""

    lesson: Lesson
    controls: Controls
    flyaround: dict[str, Any]
    selection: list[list[int]]
    messages: list[str]


def lesson_plan(lesson: Lesson, initial: Controls) -> LessonPlan:
    """The controls, mode and selection of ``lesson``, starting from ``initial`` (the app's
    initial controls: their materials and anything the link settings leave out)."""
    controls, messages = controls_from_link(lesson.link_settings, initial)
    controls = dataclasses.replace(controls, color_by=lesson.color_by, image_kind=lesson.image_kind)
    flyaround = {
        "mode": lesson.mode,
        "fly_t_s": float(lesson.fly_t_s),
        "fly_j2": bool(lesson.fly_j2),
        "fly_playing": False,
    }
    n = controls.pixels
    selection = [[r, c] for r, c in lesson.selection if 0 <= r < n and 0 <= c < n]
    return LessonPlan(lesson, controls, flyaround, selection[:MAX_SELECTED_PIXELS], messages)


class LessonGuide:
    """The lessons on a trame state: ``lesson``, the open lesson's card (None when none is open;
    the page's buttons are built from ``LESSONS``, app.ui.lessons)."""

    def __init__(self, state):
        self.state = state
        self.open_key: str | None = None
        self.state.lesson = None
        self.state.lesson_folded = False  # the card folded to one line (the page decides)
        self.state.welcome_closed = False  # a first visit's welcome line closed (app.ui.lessons)
        self.state.lesson_link_copied = ""  # what "Share this lesson" answered
        self.state.lesson_detail = False  # the card's "More detail" shown
        self.state.client_only(
            "lesson_folded", "welcome_closed", "lesson_link_copied", "lesson_detail"
        )

    def plan(self, key: Any, initial: Controls) -> LessonPlan | None:
        """What lesson ``key`` sets, or None with a message on the page if there is no such
        lesson (``key`` comes from the page: anything at all). Never raises."""
        lesson = BY_KEY.get(key) if isinstance(key, str) else None
        if lesson is None:
            self.state.input_message = f"Lessons: no lesson {echo(key)}; nothing changed"
            return None
        return lesson_plan(lesson, initial)

    def card(self, plan: LessonPlan, target_name: str) -> dict[str, str]:
        """The card of ``plan``'s lesson as the page shows it (a note when the target is not
        the one its figures are computed on)."""
        card = plan.lesson.card()
        if LESSON_TARGET not in str(target_name):
            card["note"] = (
                f"This lesson is written for the paper scene's {LESSON_TARGET}; its figures "
                f"are the MRO's, not those of {echo(target_name)}."
            )
        return card

    def opened(self, plan: LessonPlan, target_name: str) -> dict[str, Any]:
        """The state entries that show ``plan``'s lesson as open (the parent writes them with
        the lesson's controls, in one flush)."""
        self.open_key = plan.lesson.key
        return {"lesson": self.card(plan, target_name)}

    def leave(self, *_: Any, **__: Any) -> None:
        """Close the card; the scene, mode and selection stay as they are."""
        self.open_key = None
        self.state.lesson = None
