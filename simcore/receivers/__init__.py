"""Receivers: what turns the echo stage's per-pixel echoes into detections, ranges and outliers.

A receiver is one module behind one interface, selected by the scene key ``receiver.kind``:

- it reads the echo stage's hand-off, :class:`simcore.echo.EchoStage` (per lit pixel: the
  band-limited echo's peak per joule, half-maximum time and CFD slope, the strongest element's
  material and facet, and the full waveform on demand: ``EchoStage.waveform_per_j(i)``), and
  the background stage's :class:`simcore.background.Background` (per pixel of the array: the
  optical background power at the detector, all zeros without a Sun);
- :attr:`Receiver.respond` returns a :class:`Response` (per pixel: peak power at the input, the SNR
  the app shows, and the receiver's scalar noise figures), the *receiver* stage;
- :attr:`Receiver.detect` returns a :class:`Detection` (per pixel: detection probability, the
  detected mask, noise-free and measured range, range sigma; the threshold and the false-alarm
  points), the *detection* stage.

Each declares the scene values its two steps read (the stages' cache keys). Adding a receiver is
one module that builds a :class:`Receiver` and calls :func:`register` (built-in ones are named in
``BUILT_IN`` and imported on first use): nothing else changes. ``lm_apd`` (the default) is the
paper's linear-mode APD chain, Eqs. 7-28 (``simcore.receivers.lm_apd``); ``gm_apd`` a
Geiger-mode single-photon array (``simcore.receivers.gm_apd``).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..scene import DEFAULT_RECEIVER, RECEIVER_KINDS, Scene, receiver_kinds
from ..stage import Stage, readonly
from .lm_apd.detection import Outliers

if TYPE_CHECKING:
    from ..background import Background
    from ..echo import EchoStage

# kind -> the module that registers it when imported
BUILT_IN = {
    "lm_apd": "simcore.receivers.lm_apd.receiver",
    "gm_apd": "simcore.receivers.gm_apd.receiver",
}
DEFAULT_KIND = DEFAULT_RECEIVER
_REGISTERED: dict[str, Receiver] = {}


@dataclass(frozen=True, kw_only=True)
class Response:
    """A receiver's response to the echoes of one flash (the receiver stage's output).

    peak_power_w : (n,) band-limited peak received power of each lit pixel [W] (point intensity)
    snr : (n,) signal-to-noise ratio of each lit pixel [1] (points' SNR, the app's histogram and
        the summary's median; inf where the receiver has no noise)
    noise_figures : scalar diagnostics of the receiver, name (with unit) -> value
    """

    peak_power_w: np.ndarray
    snr: np.ndarray
    noise_figures: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class Detection:
    """Which lit pixels give a point and where, plus the false alarms (the detection stage's
    output). Arrays are (n,), aligned with ``EchoStage.pixel``.

    p_detect : probability of detecting the echo [1]
    detected : bool, the echo was detected inside the range gate
    range_true_m : noise-free measured range (Eq. 31, carries the waveform's bias) [m]
    range_sigma_m : range noise standard deviation [m] (inf where undefined)
    range_m : measured range, NaN where not detected [m]
    threshold_w : the arming threshold as power at the receiver input [W] (waveform plots; with
        per-pixel thresholds, a dark pixel's)
    n_false_per_pixel : expected false alarms per pixel per flash [1]: a float, the same for
        every pixel, or (pixels**2,) per pixel (flat index) where the background makes pixels
        differ
    outliers : the false-alarm points drawn for this flash
    point_attributes : a receiver's own per-point attributes, name -> (values of the lit
        pixels (n,), values of the outliers (n_out,)); the cloud carries them besides its shared
        set (the Geiger-mode receiver's ``counts`` and ``signal_pe``)
    summary_figures : a receiver's own summary figures, dotted name (with unit) -> JSON value
        (e.g. ``gm.saturated_pixel_fraction``); :meth:`simcore.result.Result.summary` adds them.
        Both built-in receivers give ``n_false_points_expected``: the false points expected in
        the cloud per frame, on the basis of the cloud's ``n_outliers``
        (docs/physics.md#false-points)
    """

    p_detect: np.ndarray
    detected: np.ndarray
    range_true_m: np.ndarray
    range_sigma_m: np.ndarray
    range_m: np.ndarray
    threshold_w: float
    n_false_per_pixel: float | np.ndarray
    outliers: Outliers
    point_attributes: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    summary_figures: dict[str, Any] = field(default_factory=dict)  # JSON values

    @property
    def n_false_expected(self) -> float:
        """Expected false alarms of the whole array per flash before the stops' limit (the
        LM-APD's noise crossings), not the cloud's false points: those are the summary figure
        ``n_false_points_expected`` [1]."""
        n = self.n_false_per_pixel
        return float(np.sum(n)) if isinstance(n, np.ndarray) else n


@dataclass(frozen=True, kw_only=True)
class Receiver:
    """One receiver kind: its two steps and the scene values each reads.

    kind : the ``receiver.kind`` value that selects it
    doc : one line for the key reference
    response_reads, detection_reads : scene -> hashable tuple of every scene value the step reads
        (besides the echo stage's key and ``receiver.kind``)
    respond : (scene, echo, background) -> Response
    detect : (scene, echo, response) -> Detection
    """

    kind: str
    doc: str
    response_reads: Callable[[Scene], tuple]
    respond: Callable[[Scene, EchoStage, Background], Response]
    detection_reads: Callable[[Scene], tuple]
    # the response is this receiver's own (a subclass of Response that its respond returned)
    detect: Callable[[Scene, EchoStage, Any], Detection]


def register(receiver: Receiver) -> Receiver:
    """Make ``receiver`` selectable as ``receiver.kind = receiver.kind``; returns it."""
    known = _REGISTERED.get(receiver.kind)
    if known is not None and known is not receiver:
        raise ValueError(f"receiver kind {receiver.kind!r} is already registered")
    _REGISTERED[receiver.kind] = receiver
    if receiver.kind not in RECEIVER_KINDS:
        RECEIVER_KINDS[len(BUILT_IN) :] = sorted({*RECEIVER_KINDS[len(BUILT_IN) :], receiver.kind})
    return receiver


def unregister(kind: str) -> None:
    """Forget a registered receiver (a built-in one comes back on its next use)."""
    _REGISTERED.pop(kind, None)
    if kind not in BUILT_IN and kind in RECEIVER_KINDS:
        RECEIVER_KINDS.remove(kind)


def kinds() -> tuple[str, ...]:
    """The valid values of ``receiver.kind``: the built-in receivers, then the registered ones."""
    return receiver_kinds()


def get(kind: str) -> Receiver:
    """The receiver registered as ``kind`` (importing a built-in one on first use)."""
    if kind not in _REGISTERED and kind in BUILT_IN:
        importlib.import_module(BUILT_IN[kind])  # registers itself
    try:
        return _REGISTERED[kind]
    except KeyError:
        raise ValueError(f"receiver.kind = {kind!r}: choose from {', '.join(kinds())}") from None


# ----------------------------------------------------------------------------------------------
# the receiver and detection stages: the scene's receiver, its two steps
# ----------------------------------------------------------------------------------------------
def _response_reads(scene: Scene) -> tuple:
    return (scene.receiver.kind, get(scene.receiver.kind).response_reads(scene))


def _detection_reads(scene: Scene) -> tuple:
    return (scene.receiver.kind, get(scene.receiver.kind).detection_reads(scene))


def stage_receiver(scene: Scene, echo: EchoStage, background: Background) -> Response:
    return _readonly_arrays(get(scene.receiver.kind).respond(scene, echo, background))


def stage_detection(scene: Scene, echo: EchoStage, response: Response) -> Detection:
    detection = get(scene.receiver.kind).detect(scene, echo, response)
    return _readonly_arrays(outside_the_gate(scene, detection))


def gate_m(scene: Scene) -> tuple[float, float]:
    """The range gate [R_st - R_gate / 2, R_st + R_gate / 2], clipped at 0 [m]."""
    half = 0.5 * scene.timing.range_gate_m
    return max(0.0, scene.gate_center_m - half), scene.gate_center_m + half


def outside_the_gate(scene: Scene, detection: Detection) -> Detection:
    """``detection`` with P_d = 0 for every lit pixel whose noise-free range lies outside the
    range gate (its echo cannot give a point, whatever its SNR), and a summary warning (one
    line under ``warnings``) saying how many and where the target is. Unchanged if none."""
    lo, hi = gate_m(scene)
    r = np.asarray(detection.range_true_m)
    out = (r < lo) | (r > hi)
    if not out.any():
        return detection
    figures = dict(detection.summary_figures)
    figures["warnings"] = [
        *figures.get("warnings", []),
        f"{int(out.sum())} of {len(r)} lit pixels see the target at {np.min(r[out]):.4g}-"
        f"{np.max(r[out]):.4g} m, outside the range gate [{lo:.4g}, {hi:.4g}] m: no point "
        "from them (P_d 0); move timing.gate_center_m or lengthen timing.range_gate_m",
    ]
    return replace(
        detection,
        p_detect=np.where(out, 0.0, detection.p_detect),
        summary_figures=figures,
    )


def _readonly_arrays(record):
    """``record`` with its array fields made read-only (stage outputs are cached and shared)."""
    readonly(*(getattr(record, f.name) for f in fields(record)))
    return record


RECEIVER = Stage(
    name="receiver",
    upstream=("echo", "background"),
    reads=_response_reads,
    compute=stage_receiver,
)
DETECTION = Stage(
    name="detection",
    upstream=("echo", "receiver"),
    reads=_detection_reads,
    compute=stage_detection,
)
