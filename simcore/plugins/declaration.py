"""What a receiver declares: one :class:`Receiver` object, in its own package, says everything
the rest of the simulator needs to know about it.

- its parameter section (:class:`Section`: the scene table, e.g. ``[gm]``, a frozen dataclass
  whose fields are declared with :func:`simcore.scene.fields.key`: unit, range, doc; the key
  reference, ``lmapd keys`` and the scene files read it from here) and the rules between its
  keys (``check_scene``, run when a scene selects the receiver);
- its two stages, the receiver and the detection step (``respond``, ``detect``) and the scene
  values each reads (``response_reads``, ``detection_reads``: the stages' cache keys);
- the summary figures and the per-point attributes it adds (:class:`Figure`, :class:`Attribute`);
- what the app shows of it: its controls (:class:`Control`), its stats rows (:class:`StatsRow`),
  the series it adds to the pixel chart (:class:`Series`) and its glossary entries.

A step may be given as a function or, so that declaring a receiver loads none of its physics, as
``"package.module:function"``, imported on first use. This module loads nothing but the standard
library: the scene reads the declarations to know its sections.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

# a step: the function itself, or "package.module:function" (imported on first use)
Step = Callable[..., Any] | str


def resolve(step: Step) -> Callable[..., Any]:
    """The function a step names (``"package.module:function"``), or the step itself."""
    if callable(step):
        return step
    module, _, name = step.partition(":")
    if not module or not name:
        raise ValueError(
            f"a receiver step is a function or 'package.module:function', not {step!r}"
        )
    return getattr(importlib.import_module(module), name)


@dataclass(frozen=True, kw_only=True)
class Section:
    """A receiver's own scene table: ``name`` (``gm`` for the keys ``gm.*``) and the frozen
    dataclass of its keys (each field a :func:`simcore.scene.fields.key`)."""

    name: str
    keys: type
    doc: str = ""


@dataclass(frozen=True, kw_only=True)
class Figure:
    """A summary figure the receiver adds (``Result.summary()``, ``lmapd simulate --summary``):
    its dotted name, unit and one line of doc."""

    name: str
    unit: str
    doc: str


@dataclass(frozen=True, kw_only=True)
class Attribute:
    """A per-point attribute the receiver adds to the cloud (``Detection.point_attributes``)."""

    name: str
    unit: str
    doc: str


@dataclass(frozen=True, kw_only=True)
class Control:
    """A control the app shows while the receiver is selected: the state's ``name`` (in display
    units), the scene ``key`` it sets, ``scale`` from the display unit to the key's (1e-9: ns to
    s), the label, unit, range and slider step, and the glossary entry its label opens."""

    name: str
    key: str
    label: str
    unit: str
    lo: float
    hi: float
    step: float
    scale: float = 1.0
    integer: bool = False
    log_slider: bool = False
    terms: tuple[str, ...] = ()  # the glossary's terms its info button opens


@dataclass(frozen=True, kw_only=True)
class StatsRow:
    """A row of the app's stats table: its label and the value's text, ``str.format`` over the
    frame's summary (``{summary[n_points]}``), its receiver's noise figures
    (``{noise[events]:,.0f}``) and its scene (``{scene[gm][pulses]}``). A row whose fields are
    missing is left out."""

    label: str
    text: str


@dataclass(frozen=True, kw_only=True)
class Series:
    """A series of the app's pixel chart for this receiver: how it is drawn (``"bars"``,
    ``"solid"``, ``"dotted"``) and what it shows; the chart's caption lists them."""

    style: str
    doc: str = ""

    def text(self) -> str:
        return f"{self.style}: {self.doc}" if self.doc else self.style


@dataclass(frozen=True, kw_only=True)
class FrameLoad:
    """What one frame of a receiver will record, estimated before its receiver stage runs: the
    ``count`` of ``units`` (avalanches), the memory each takes [B], whether the core's own limits
    hold (False: the core would refuse the frame), and which controls bring it down."""

    count: float
    units: str
    bytes_each: float
    within_core_limits: bool
    advice: str


@dataclass(frozen=True, kw_only=True)
class Receiver:
    """One receiver kind, declared in its own package (see the module's doc).

    kind : the ``receiver.kind`` value that selects it
    doc : one line for the key reference
    label : its name in the app's receiver choice ("Geiger mode")
    short : a short name for the app's CSS classes (``receiver-gm``, ``gm-controls``)
    hint : the app's caption under its controls
    glossary : (term, explanation) pairs the app's glossary adds: a new term is a new entry; a
        term already there (the page's, an earlier receiver's) gets the text after its own, one
        space between (the receiver's half of a shared word: Geiger mode's SNR)
    description : the app's stats row "Receiver", formatted as a :class:`StatsRow`'s text
        ("Geiger-mode array, {scene[gm][pulses]} pulses")
    section : its own scene table, or None (it reads only the shared sections)
    check_scene : (scene) -> None, raises SceneError: the rules between its keys (or None)
    response_reads, detection_reads : (scene) -> hashable tuple of every scene value the step
        reads (besides the echo stage's key and ``receiver.kind``)
    respond : (scene, echo, background) -> Response (the receiver stage)
    detect : (scene, echo, response) -> Detection (the detection stage)
    summary_figures, point_attributes : what it adds to the summary and to the cloud
    snr_name, snr_stats_label : its SNR's name (the app's SNR histogram) and stats row label
    threshold_on_snr_axis : its threshold is TNR on the SNR axis (False: in other units)
    controls, stats_rows : what the app shows of it
    chart : which of the app's pixel charts shows it: ``waveform`` (the band-limited echo, the
        threshold and the detected range) or ``counts`` (photon-count histograms over a
        frame's pulses); chart_title, chart_series (the caption: what each series shows) and
        snr_caption: their words
    counts : (result) -> the frame's counts as the ``counts`` chart draws them (its gate, bins,
        pulses, and per pixel the measured, expected and arriving counts), for that chart
    stops_taken : (result) -> (n_lit,) the range [m] of the false alarm that took each lit
        pixel's stop, NaN where none did (a receiver with a limited number of stops), or None
    frame_load : (scene, echo, background) -> :class:`FrameLoad`, what a frame will cost before
        its receiver stage runs (the app refuses frames over its budget), or None (no check)
    frame_pulses_key : the key of its pulses per frame (a frame sums that many pulses; the
        design studies' total pulse energy), None: one pulse a frame
    pulses_needed : (scene, result, p_target, max_pulses) -> the pulses a frame needs for
        P_d >= p_target in the median lit pixel (``lmapd compare``; inf beyond max_pulses), or
        None: independent single flashes, from the per-flash P_d
    range_bias_figure, range_sigma_figure : the summary figures of its predicted range bias
        (None: unbiased) and range sd (``lmapd compare``)
    """

    kind: str
    doc: str
    response_reads: Step
    respond: Step
    detection_reads: Step
    detect: Step
    label: str = ""
    short: str = ""
    hint: str = ""
    glossary: tuple[tuple[str, str], ...] = ()
    description: str = ""
    section: Section | None = None
    check_scene: Step | None = None
    summary_figures: tuple[Figure, ...] = ()
    point_attributes: tuple[Attribute, ...] = ()
    snr_name: str = "SNR"
    snr_stats_label: str = "Median SNR"
    threshold_on_snr_axis: bool = True
    controls: tuple[Control, ...] = ()
    stats_rows: tuple[StatsRow, ...] = ()
    chart: str = "waveform"
    chart_title: str = ""
    chart_series: tuple[Series, ...] = ()
    snr_caption: str = ""
    counts: Step | None = None
    stops_taken: Step | None = None
    frame_load: Step | None = None
    frame_pulses_key: str | None = None
    pulses_needed: Step | None = None
    range_bias_figure: str | None = None
    range_sigma_figure: str = "range_sigma_m_median"
