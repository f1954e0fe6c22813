"""The paper scene's receiver and pulse as the Monte Carlo tests (and scripts/plot_mc_agreement.py)
drive the waveform model directly: one place for the constants they share."""

from __future__ import annotations

import dataclasses

import simcore
from simcore import echo
from simcore.receivers.lm_apd import apd as receiver
from simcore.receivers.lm_apd import timing

SCENE = simcore.Scene()
RX = receiver.receiver_model(SCENE.detector, SCENE.amplifiers, SCENE.laser.wavelength_m)
# the same receiver with negligible signal shot noise (thermal + dark limited)
RX_THERMAL = dataclasses.replace(RX, excess_noise=1e-9)
TAU = SCENE.laser.pulse_width_s  # pulse width [s]
B = SCENE.detector.bandwidth_hz  # receiver bandwidth [Hz]
E = SCENE.laser.pulse_energy_j  # pulse energy [J]
SHAPE = echo.pulse_shape(TAU, echo.A_FWHM, B)
DT = echo.default_time_step_s(TAU, B)  # waveform time step [s]
T_D = timing.cfd_delay_s(SHAPE)  # CFD delay [s]
K_ATT = SCENE.timing.cfd_fraction  # CFD fraction [1]
T_T = SCENE.timing.resolution_s  # timing resolution [s]
