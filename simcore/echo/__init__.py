"""Per-pixel echoes (Eqs. 4, 5, 29-31): sub-ray elements, the band-limited echo's features and the
echo stage. All waveforms here are per joule of pulse energy: the received power scales linearly
with the energy, so a pulse-energy change never re-runs this stage.

``elements``  illumination gain and Eq. 30 weights; splitting and merging elements
``features``  peak, half-maximum time and CFD slope of each echo (exact delays): the compiled
              kernel where numba is available (``kernel``), else the numpy path
``stage``     the echo stage: what it hands a receiver (:class:`EchoStage`), its declaration

The pulse itself (Eq. 1, the band limit) is ``simcore.pulse``; its names are re-exported here.
The model: docs/physics.md#echo (docs/physics.md#eq-29, docs/physics.md#eq-30).
"""

from ..pulse import (
    A_FWHM,
    A_PAPER,
    PulseShape,
    band_limit_sigma_s,
    default_time_step_s,
    filtered_pulse_w,
    pulse_power_w,
    pulse_shape,
)
from .elements import element_weights, illumination_gain, merge_elements, split_elements
from .features import EchoFeatures, compiled_kernel, echo_features
from .stage import ECHO, EchoStage, echo_waveform, stage_echo

__all__ = [
    "A_FWHM",
    "A_PAPER",
    "ECHO",
    "EchoFeatures",
    "EchoStage",
    "PulseShape",
    "band_limit_sigma_s",
    "compiled_kernel",
    "default_time_step_s",
    "echo_features",
    "echo_waveform",
    "element_weights",
    "filtered_pulse_w",
    "illumination_gain",
    "merge_elements",
    "pulse_power_w",
    "pulse_shape",
    "split_elements",
    "stage_echo",
]
