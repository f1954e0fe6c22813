"""The Geiger-mode (single-photon) APD array registered as ``receiver.kind = "gm_apd"``: its
two steps, the receiver stage (:mod:`.response`) and the detection stage (:mod:`.detection`).
"""

from __future__ import annotations

from .. import Receiver, register
from .detection import _detect_with_warnings, _detection_reads
from .response import _response_reads, respond

RECEIVER = register(
    Receiver(
        kind="gm_apd",
        doc="Geiger-mode single-photon APD array: photon-counting histograms of gm.pulses pulses",
        response_reads=_response_reads,
        respond=respond,
        detection_reads=_detection_reads,
        detect=_detect_with_warnings,
    )
)
