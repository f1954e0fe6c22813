"""The Geiger-mode (single-photon) APD array, ``receiver.kind = "gm_apd"``, by concern:

- :mod:`.frame`: the photon budget, the gate and the frame's expected load (its refusal);
- :mod:`.events`: the avalanches of every pixel and pulse (dead time, jitter, TDC bins,
  afterpulsing, crosstalk); :mod:`.limits`: the chance to be armed, the memory per avalanche;
- :mod:`.histogram`: the sparse per-pixel histogram, its peak windows and centroid estimator;
- :mod:`.response`: the receiver stage; :mod:`.records`: its response and detection records;
- :mod:`.windows`: the peak window, its expected counts, thresholds and predicted P_d;
- :mod:`.detection`: the detection stage; :mod:`.false_points`: the expected false points;
- :mod:`.figures`: the predicted and measured ``gm.*`` figures;
- :mod:`.pileup` (with :mod:`.expected`, :mod:`.coates`, :mod:`.first_photon`): the range the
  histogram gives at any flux, and the first-photon correction;
- :mod:`.receiver`: the receiver itself, its two steps registered as ``gm_apd``.

The model: docs/physics.md#geiger-mode, docs/physics.md#gm-pileup.
"""
