"""The linear-mode APD receiver (``receiver.kind = "lm_apd"``), the paper's chain (Eqs. 7-31):

- :mod:`.apd`: the APD and its amplifier chain (responsivity, gain, noise and SNR, Eqs. 7-18);
- :mod:`.timing`: half-maximum ranging, the constant-fraction discriminator and the range errors
  (Eqs. 19, 24-26, 31);
- :mod:`.detection`: detection probability and false alarms (Eqs. 27-28), drawn for one flash;
- :mod:`.montecarlo`: the waveform Monte Carlo model (noisy currents through the discriminator);
- :mod:`.receiver`: the receiver itself, its two steps registered as ``lm_apd``.
"""
