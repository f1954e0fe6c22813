"""The linear-mode APD receiver (``receiver.kind = "lm_apd"``), the paper's chain (Eqs. 7-31):

- :mod:`.apd`: the APD and its amplifier chain (responsivity, gain, noise and SNR, Eqs. 7-18);
- :mod:`.timing`: half-maximum ranging, the constant-fraction discriminator and the range errors
  (Eqs. 19, 24-26, 31);
- :mod:`.detection`: detection probability and false alarms (Eqs. 27-28), drawn for one flash;
- :mod:`.montecarlo`: the waveform Monte Carlo model (noisy currents through the discriminator);
- :mod:`.receiver`: the receiver's two steps (respond, detect) and the scene values they read.

Here: its declaration, ``RECEIVER`` (:mod:`simcore.plugins.declaration`), which the registry
loads by name. Its keys are the shared sections ``detector``, ``amplifiers`` and ``timing`` (the
paper's instrument), so it declares no section of its own.
"""

from __future__ import annotations

from ...plugins.declaration import Figure, Receiver, Series

_STEPS = f"{__name__}.receiver"

RECEIVER = Receiver(
    kind="lm_apd",
    doc="linear-mode APD and amplifier chain (Eqs. 7-28)",
    response_reads=f"{_STEPS}:_response_reads",
    respond=f"{_STEPS}:respond",
    detection_reads=f"{_STEPS}:_detection_reads",
    detect=f"{_STEPS}:detect",
    summary_figures=(
        Figure(
            name="n_false_points_expected",
            unit="1",
            doc="false points expected in the cloud per frame (after the stops' limit)",
        ),
    ),
    label="Linear mode",
    short="lm",
    description="linear-mode APD array",
    # the app's glossary: its own words (its timing), and its halves of the shared ones (after
    # the page's lead, before the other receivers')
    glossary=(
        (
            "SNR",
            "the echo's peak power over the noise's standard deviation σn, in one flash (linear "
            "mode). A pixel needs an SNR above about the TNR to be detected.",
        ),
        (
            "CFD",
            "Constant-fraction discriminator: times an echo where it reaches a fixed fraction of "
            "its own peak (a delayed copy minus a scaled copy crosses zero), so the time does not "
            "move with the echo's strength.",
        ),
        (
            "Half-maximum time",
            "The time at which the echo first reaches half of its peak (◆ on the chart): the "
            "linear-mode range is c t / 2 from it.",
        ),
        ("Background light", "its shot noise adds to the noise (linear mode),"),
    ),
    stops_taken=f"{__name__}.taken:stops_taken_m",
    chart="waveform",
    chart_title="Echo waveforms of the selected pixels",
    chart_series=(
        Series(style="solid", doc="received (band-limited)"),
        Series(style="dotted", doc="unfiltered"),
        Series(style="dashed", doc="emitted pulse delayed by 2R/c"),
        Series(style="◆ half-maximum time"),
        Series(style="vertical line", doc="detected range"),
        Series(style="dash-dot", doc="threshold (TNR × σn)"),
        Series(
            style="by day, orange",
            doc="the background and the noise band (on a right-hand axis when too small to "
            "see beside the echo)",
        ),
    ),
    snr_caption="SNR of the pixels with an echo (one flash; the red line: TNR)",
)
