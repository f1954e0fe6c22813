"""Lessons: one-click scenes that teach, each with a card saying what to look at and why, a child
of the app's logic.

A lesson is a data record: its scene as the settings of a shared link (the names of
``lmapd simulate --set``, in SI units, read by ``app.logic.links.controls_from_link``), the display
choices, the mode (single frame or a fly-around frame), the pixels to select, and a short card:
what to look at, the physics behind it, what to try next, and the section of docs/physics.md that
explains it. Every number on a card is a named figure of the record, and
tests/app/test_app_lessons.py computes each one again from the simulation: the card's text
rendered from the computed figures must equal the text rendered from the record's.

The lessons are written for the paper scene (the MRO at 500 m, ``lmapd simulate`` with no
options): a lesson starts from the app's initial controls and sets every control it depends on
(``PAPER_SETTINGS`` and its own), so it gives the same frame whatever the user changed before.
With another target (the drop-down, an upload, ``--scene``) a lesson still sets its controls, and
its card says that its figures are the MRO's.

The parent (``AppLogic``) registers the page's ``open_lesson`` and ``leave_lesson`` triggers and
calls :meth:`LessonGuide.plan` (what a lesson sets), :meth:`LessonGuide.opened` (the card on the
page) and :meth:`LessonGuide.leave`. Leaving only hides the card: the scene stays as it is.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from app.logic.links import controls_from_link
from app.state import MAX_SELECTED_PIXELS, Controls, echo

MJ = 1e-3  # J per mJ: a pulse energy written as ``0.1 * MJ`` shows as 0.1 mJ on the slider
NM = 1e-9  # m per nm: a filter width written as ``100 * NM`` shows as 100 nm
LESSON_TARGET = "Mars Reconnaissance Orbiter"  # the target whose figures the cards give
# the views a card can point at: its name on the card, and the page's element (app.ui)
VIEWS: dict[str, tuple[str, str]] = {
    "waveform": ("the waveform chart", ".waveform-card"),
    "array": ("the detector array image", ".array-card"),
    "cloud": ("the point cloud", ".cloud-card"),
    "scene": ("the 3D scene", ".scene-card"),
    "stats": ("the statistics", ".stats-card"),
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
    look, why, try_next : the card's three paragraphs, ``str.format`` templates of ``figures``
        (a template holds no digit of its own: every number on the card is a figure)
    reference : the section that explains it: ``docs/physics.md``, ``#``, one of its anchors
    reference_title : that section's title
    figures : the card's numbers, each computed again by the tests
    color_by, image_kind : the display choices (``app.state.COLOR_BY``, ``IMAGE_KINDS``)
    mode, fly_t_s, fly_j2 : single frame, or the fly-around frame at ``fly_t_s`` [s]
    view : the view its card is about (a key of ``VIEWS``): the page brings it into sight
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
    figures: Mapping[str, float] = field(default_factory=dict)
    color_by: str = "range"
    image_kind: str = "range"
    mode: str = "single"
    fly_t_s: float = 0.0
    fly_j2: bool = False
    view: str = "waveform"

    @property
    def link_settings(self) -> dict[str, Any]:
        """Every control of the lesson's scene as link settings (SI units)."""
        return {**PAPER_SETTINGS, **self.settings}

    def card(self, figures: Mapping[str, float] | None = None) -> dict[str, str]:
        """The card's text, with ``figures`` (default: the record's) in its templates."""
        values = self.figures if figures is None else figures
        return {
            "key": self.key,
            "title": self.title,
            "look": self.look.format_map(values),
            "why": self.why.format_map(values),
            "try_next": self.try_next.format_map(values),
            "reference": self.reference,
            "reference_title": self.reference_title,
            "note": "",
            "view": VIEWS[self.view][0],
            "view_selector": VIEWS[self.view][1],
        }


LESSONS: tuple[Lesson, ...] = (
    Lesson(
        key="double-peak",
        title="Two echoes in one pixel: the dish rim over the bus",
        settings={},
        selection=((113, 131), (114, 124)),
        look=(
            "The waveform chart: each selected pixel's echo has two peaks. The first pixel sees "
            "the rim of the high-gain dish at {near_m:.1f} m and the structure behind it at "
            "{far_m:.1f} m, {gap_m:.2f} m further; the second pixel the same rim, {gap2_m:.2f} m "
            "in front of the structure."
        ),
        why=(
            "A pixel's echo is the sum of copies of the pulse returned by every surface it sees, "
            "each delayed by its own round trip. Surfaces {gap_m:.2f} m apart in depth return "
            "copies {gap_ns:.1f} ns apart, more than the width of the band-limited pulse "
            "({pulse_ns:.2f} ns at half maximum, {pulse_m:.2f} m of range): two peaks. The range "
            "is measured on the first rise, at half maximum: {range_m:.1f} m, the rim. Only "
            "{n_double} of the {n_lit:,} pixels with an echo have two peaks: most pixels see one "
            "surface, or depths closer together than the pulse is long."
        ),
        try_next=(
            "Change Pitch by one degree either way: the rim moves off these pixels and each "
            "echo keeps one peak, the dish's or the structure's. Shift-click along the dish's "
            "new edge to find two again; the array image's Multi-peak mode marks every pixel "
            "with two."
        ),
        reference="docs/physics.md#eq-29",
        reference_title="Eq. 29, the pixel's impulse response",
        figures={
            "near_m": 497.8,
            "far_m": 499.2,
            "gap_m": 1.37,
            "gap2_m": 1.00,
            "gap_ns": 9.2,
            "pulse_ns": 5.76,
            "pulse_m": 0.86,
            "range_m": 497.9,
            "n_double": 15,
            "n_lit": 13890,
        },
    ),
    Lesson(
        key="panels-azimuth",
        view="array",
        title="Solar panels fade as the azimuth grows",
        settings={"azimuth_deg": 3.0, "pulse_energy_j": 0.1 * MJ},
        selection=((163, 49), (172, 200)),
        image_kind="peak_power",
        look=(
            "The array image shows each pixel's peak power. Turned by {az:g}°, the right panel "
            "still echoes ({det_right:,} of its {n_right:,} pixels give a point) while the left "
            "one has faded ({det_left:,} of {n_left:,}). One pixel of each is selected: compare "
            "their echoes with the threshold (dash-dot)."
        ),
        why=(
            "The panels lie either side of the boresight, so the left one is now seen "
            "{inc_left:.1f}° off its normal and the right one {inc_right:.1f}°. A solar panel "
            "reflects in a narrow specular lobe (A = {spec:g} /sr, down by a factor e where "
            "tan θ equals its slope s, at {lobe_deg:.1f}°) over a weak diffuse term "
            "(B = {diffuse:g} /sr): at {inc_right:.1f}° its reflectance keeps {rho_right:.0f} % "
            "of its value head-on, at {inc_left:.1f}° {rho_left:.0f} %. With a {energy_mj:g} mJ "
            "pulse that decides it: head-on {det0:,} of the {n0:,} panel pixels give a point, "
            "here {det:,} of {n_panel:,}, at {az_more:g}° {det_more:,}."
        ),
        try_next=(
            "Drag Azimuth back to zero and on to {az_more:g}°, then raise the Pulse energy: "
            "with more light the weak diffuse term is enough, and the panels come back."
        ),
        reference="docs/physics.md#eq-6",
        reference_title="Eq. 6, the four-parameter BRDF (Table 1: the solar panel)",
        figures={
            "az": 3.0,
            "energy_mj": 0.1,
            "n_panel": 6611,
            "det": 3238,
            "det_left": 413,
            "det_right": 2825,
            "n_left": 3386,
            "n_right": 3225,
            "inc_left": 3.6,
            "inc_right": 2.4,
            "rho_left": 25,
            "rho_right": 52,
            "lobe_deg": 2.9,
            "spec": 0.5,
            "diffuse": 0.03,
            "n0": 6604,
            "det0": 6390,
            "az_more": 5.0,
            "det_more": 8,
        },
    ),
    Lesson(
        key="distance",
        view="stats",
        title="Points lost with distance (and why not as R⁻² everywhere)",
        settings={"distance_m": 3000.0},
        selection=((137, 111), (134, 125), (114, 125)),
        look=(
            "At {d:,.0f} m the MRO covers {hit:,} pixels and gives {pts:,} target points; at "
            "{d_ref:.0f} m it covered {hit_ref:,} and gave {pts_ref:,}. The selected pixels see a "
            "solar panel (SNR {snr_panel:.1f}), the bus (SNR {snr_bus:.1f}) and the dish "
            "(SNR {snr_dish:.1f}: below the TNR of {tnr:g}, no point)."
        ),
        why=(
            "{ratio:g} times further, the target's image has a {ratio_sq:g}th of the area: "
            "{hit:,} pixels against {hit_ref:,} / {ratio_sq:g} = {hit_scaled:,.0f} (its edge "
            "pixels count whole). Each pixel's echo falls as R⁻² too: the irradiance and the "
            "aperture's solid angle fall as R⁻², the patch a pixel sees grows as R². So the "
            "median SNR drops from {snr_ref:.0f} to {snr:.1f} (by less than {ratio_sq:g}: close "
            "in the echo's own shot noise dominates, and it shrinks with the echo), and pixels "
            "near the threshold give no point: {pts:,} of {hit:,}. Closer in, the points fall "
            "slower than R⁻²: at {d_close:.0f} m the {fov_close:.1f} m field of view holds only "
            "part of the target, {hit_close:,} pixels, not {hit_close_r2:,}. The false alarms "
            "do not follow the target: {out:,} outliers here, {out_ref:,} at {d_ref:.0f} m."
        ),
        try_next=(
            "Drag Distance from {d_close:.0f} m out to the far end, watching the point count and "
            "the SNR histogram slide under the TNR line."
        ),
        reference="docs/physics.md#eq-30",
        reference_title="Eq. 30, the weight of one surface element (the lidar equation)",
        figures={
            "d": 3000.0,
            "d_ref": 500.0,
            "hit": 483,
            "pts": 279,
            "hit_ref": 14526,
            "pts_ref": 13617,
            "snr_panel": 13.7,
            "snr_bus": 7.4,
            "snr_dish": 1.4,
            "tnr": 5.0,
            "ratio": 6.0,
            "ratio_sq": 36.0,
            "hit_scaled": 404,
            "snr": 7.4,
            "snr_ref": 103,
            "d_close": 250.0,
            "fov_close": 7.5,
            "hit_close": 33316,
            "hit_close_r2": 58104,
            "out": 139,
            "out_ref": 133,
        },
    ),
    Lesson(
        key="tnr-trade",
        view="cloud",
        title="The TNR trade: dropped pixels against false alarms",
        settings={"pulse_energy_j": 0.05 * MJ, "tnr": 4.0},
        selection=((124, 141),),
        color_by="outlier",
        look=(
            "The point cloud coloured by outlier flag: at TNR {tnr:g} the {gate_m:,.0f} m range "
            "gate fills with {out4:,} false points, and {drop4:,} of the {n_lit:,} pixels with "
            "an echo give no point. The selected pixel's echo peaks at SNR "
            "{snr_px:.1f}; the dash-dot line is the threshold."
        ),
        why=(
            "A pixel fires when its signal crosses TNR times the noise σ. Noise alone crosses it "
            "at Rice's rate, which falls as exp(−½ TNR²): {nf4:,.0f} false alarms expected per "
            "flash at TNR {tnr:g}, {nf5:,.0f} at {tnr5:g}, {nf6:.1f} at {tnr6:g}. Each pixel has "
            "one stop, so a false alarm before the echo loses the echo too. A higher threshold "
            "misses weak echoes instead. Outliers / dropped pixels at TNR {tnr:g}: {out4:,} / "
            "{drop4:,}; {tnr5:g}: {out5:,} / {drop5:,}; {tnr6:g}: {out6:,} / {drop6:,}; "
            "{tnr8:g}: {out8:,} / {drop8:,}. With a {energy_mj:g} mJ pulse the echoes are weak "
            "(median SNR {snr_med:.1f}): no threshold avoids both."
        ),
        try_next=(
            "Drag TNR up to {tnr5:g}, {tnr6:g} and {tnr8:g}, then raise the Pulse energy: "
            "stronger echoes leave room for a high threshold."
        ),
        reference="docs/physics.md#eq-28",
        reference_title="Eq. 28, false alarms (and Eq. 27, the detection probability)",
        figures={
            "tnr": 4.0,
            "energy_mj": 0.05,
            "gate_m": 1000.0,
            "n_lit": 13890,
            "snr_px": 6.1,
            "snr_med": 4.8,
            "out4": 11878,
            "drop4": 6996,
            "nf4": 14043,
            "tnr5": 5.0,
            "out5": 143,
            "drop5": 7073,
            "nf5": 156,
            "tnr6": 6.0,
            "out6": 0,
            "drop6": 8776,
            "nf6": 0.6,
            "tnr8": 8.0,
            "out8": 0,
            "drop8": 12974,
        },
    ),
    Lesson(
        key="pixel-count",
        view="cloud",
        title="Pixel count against detail",
        settings={"pixels": 64},
        selection=((28, 32), (28, 33)),
        look=(
            "At {n} × {n} each pixel covers {cm:.1f} cm of the target at {d:.0f} m: {pts:,} "
            "target points, and the dish and struts blur into blocks. The two selected pixels "
            "straddle the dish's rim and the structure behind it: two peaks ({dbl} of the "
            "{n_lit:,} pixels with an echo have two)."
        ),
        why=(
            "A pixel's angle is the field of view over the pixels per side (Eqs. 22-23): "
            "{fov_mrad:g} mrad / {n} = {ifov_mrad:.3f} mrad, {cm:.1f} cm at {d:.0f} m; at "
            "{n_ref} × {n_ref}, {cm_ref:.1f} cm and {pts_ref:,} points. The same {energy_mj:g} "
            "mJ pulse is shared by {ratio:g} times as many pixels there, so each echo is weaker: "
            "median SNR {snr:.0f} here, {snr_ref:.0f} at {n_ref} × {n_ref}. False alarms come at "
            "a rate per pixel: {out} outliers here, {out_ref} there."
        ),
        try_next=(
            "Drag Pixels to {n_ref} and beyond: more points and finer detail, weaker echoes, and "
            "each frame takes longer."
        ),
        reference="docs/physics.md#eq-22",
        reference_title="Eqs. 22-23, field of view, pixel angle and focal length",
        figures={
            "n": 64,
            "n_ref": 256,
            "d": 500.0,
            "cm": 23.4,
            "cm_ref": 5.9,
            "fov_mrad": 30.0,
            "ifov_mrad": 0.469,
            "pts": 981,
            "pts_ref": 13617,
            "dbl": 9,
            "n_lit": 987,
            "energy_mj": 5.0,
            "ratio": 16.0,
            "snr": 337,
            "snr_ref": 103,
            "out": 9,
            "out_ref": 133,
        },
    ),
    Lesson(
        key="flyaround-edge-on",
        view="array",
        title="Fly-around: the solar panels edge-on",
        settings={},
        selection=((101, 13), (102, 26)),
        mode="flyaround",
        fly_t_s=1500.0,
        look=(
            "Fly-around frame at t = {t:.0f} s, {d:.1f} m from the MRO (the field of view spans "
            "{fov_m:.1f} m: part of the target). The solar panels are edge-on, a line a pixel or "
            "two high: {n_px} pixels see a panel and {n_det} give a point, {n_rim} of them on "
            "the panel's rim. The first selected pixel sees the rim (a point), the second the "
            "panel's face at grazing incidence (none)."
        ),
        why=(
            "The MRO holds its attitude in its orbit frame while the lidar's orbit carries it "
            "around the target, so the line of sight sweeps over the panels: here it meets them "
            "{inc:.1f}° from their normal, {graze:.1f}° from their plane. A face seen at grazing "
            "incidence shows almost no area and reflects almost nothing back (Eq. 6); the "
            "rim's facets face the lidar ({inc_rim:.0f}° from their normal). At t = {t0:.0f} s "
            "the panels were seen at {inc0:.0f}°: {n_px0:,} pixels, {n_det0:,} points."
        ),
        try_next=(
            "Drag the time slider or press play: the panels turn edge-on again at "
            "t = {t_again:.0f} s ({inc_again:.1f}° from their normal)."
        ),
        reference="docs/physics.md#flyaround",
        reference_title="The fly-around (Table 3's orbits, the attitudes and the relative pose)",
        figures={
            "t": 1500.0,
            "d": 222.6,
            "fov_m": 6.7,
            "n_px": 165,
            "n_det": 92,
            "n_rim": 90,
            "inc": 89.6,
            "inc_rim": 28,
            "graze": 0.4,
            "t0": 0.0,
            "inc0": 59,
            "n_px0": 9200,
            "n_det0": 8947,
            "t_again": 4500.0,
            "inc_again": 88.4,
        },
    ),
    Lesson(
        key="day-night",
        view="array",
        title="Day against night: sunlight through the filter",
        settings={
            "sun.mode": "manual",
            "sun.azimuth_deg": 0.0,
            "sun.elevation_deg": 90.0,
            "receive.filter_width_m": 100 * NM,
        },
        selection=((174, 51), (73, 99)),
        image_kind="background",
        look=(
            "The array image shows the background light. The Sun is behind the lidar "
            "({sun_angle:.0f}° from the line of sight), so the MRO is lit all over ({sunlit:,} "
            "of the {hit:,} pixels that see it): the selected "
            "panel pixel collects {bg_panel_nw:.0f} nW, the dish pixel {bg_dish_nw:.1f} nW (its "
            "curved face sends the sunlight elsewhere), the day-side Earth behind the target "
            "{bg_earth_nw:.0f} nW per pixel. The waveform chart draws the panel pixel's "
            "background level: steady, so the AC-coupled readout removes it, but its shot "
            "noise stays."
        ),
        why=(
            "Sunlight in the filter's band adds its shot noise to each pixel's noise: through "
            "this {fw:.0f} nm filter up to {share_max:.0f} % of the noise variance (median "
            "{share_med:.0f} %). The threshold is one level for the array, set on a dark pixel, "
            "so sunlit pixels cross it more often: {out:,} outliers against {out_night} at "
            "night, and {drop:,} pixels dropped against {drop_night} (a false alarm takes a "
            "pixel's one stop). A {fw_narrow:.0f} nm filter lets in {fw_ratio:.0f} times less "
            "light: {share_narrow:.1f} % of the noise, {out_narrow} outliers."
        ),
        try_next=(
            "Switch the Sun to None (night) and back; narrow the Filter width; lower the Sun's "
            "elevation, away from the lidar's direction."
        ),
        reference="docs/physics.md#background-noise",
        reference_title="The receiver with background light",
        figures={
            "sun_angle": 0.0,
            "sunlit": 14448,
            "hit": 14526,
            "bg_panel_nw": 78,
            "bg_dish_nw": 4.1,
            "bg_earth_nw": 14,
            "fw": 100.0,
            "share_max": 37,
            "share_med": 29,
            "out": 834,
            "drop": 713,
            "out_night": 133,
            "drop_night": 273,
            "fw_narrow": 1.0,
            "fw_ratio": 100.0,
            "share_narrow": 0.6,
            "out_narrow": 157,
        },
    ),
    Lesson(
        key="lm-vs-gm",
        title="Linear mode against Geiger mode: a few photons, far away",
        settings={
            "receiver.kind": "gm_apd",
            "distance_m": 3000.0,
            "pulse_energy_j": 0.05 * MJ,
            "gm.attenuation_db": 0.0,
        },
        selection=((137, 111),),
        look=(
            "A Geiger-mode array at {d:,.0f} m with a {energy_mj:g} mJ pulse: {gm_pts} of the "
            "{lit} lit pixels give a point, and none is false. The chart shows the selected "
            "pixel's photon counts over the {pulses} pulses of the frame. Switch the Receiver to "
            "Linear mode: {lm_pts} target points, {lm_out} false ones."
        ),
        why=(
            "A Geiger-mode pixel fires on a single photoelectron. Here the median pixel gets "
            "{pe:.1f} per pulse, and the densest pulse-wide window of its histogram stands out "
            "from the background counts expected there. A linear-mode pixel must see its echo "
            "above TNR times its noise in one flash: at this energy the median SNR is "
            "{lm_snr:.2f}. The price is in the range: after an avalanche a pixel is dead for "
            "{dead_ns:,.0f} ns, longer than the echo, so each pulse records its earliest photon "
            "and the histogram leans to the echo's onset. The median range error is "
            "{gm_err:.2f} m (after Coates' correction), against {lm_err:.3f} m for the linear "
            "mode at {lm_energy_mj:g} mJ, where it gives {lm_pts_bright} points; and a frame "
            "takes {pulses} pulses instead of one."
        ),
        try_next=(
            "Switch the Receiver to Linear mode and raise the Pulse energy until the points come "
            "back; in Geiger mode, lower the pulses per frame or raise the dark count rate."
        ),
        reference="docs/physics.md#geiger-mode",
        reference_title="Beyond the paper: the Geiger-mode receiver",
        figures={
            "d": 3000.0,
            "energy_mj": 0.05,
            "gm_pts": 472,
            "lit": 483,
            "pulses": 100,
            "lm_pts": 0,
            "lm_out": 140,
            "pe": 8.1,
            "lm_snr": 0.09,
            "dead_ns": 1000,
            "gm_err": 0.28,
            "lm_err": 0.020,
            "lm_energy_mj": 5.0,
            "lm_pts_bright": 279,
        },
    ),
)

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
        self.state.client_only("lesson_folded")

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
