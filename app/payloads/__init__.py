"""What each view draws, built from a simcore Result in the worker thread: the 3D scene, the point
cloud, the detector-array image, the waveform chart and the stats (``views``), and their compact
encodings for the page (``encode``). The engine uses them; nothing here knows the logic or the
UI."""
