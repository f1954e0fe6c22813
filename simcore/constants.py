"""Physical constants [SI units], one per line with its unit and source.

The four the model uses are exact by definition since the 2019 revision of the SI (CODATA 2018
and 2022 list them as exact). The values are scipy.constants' to the last bit (a test checks), so
results do not depend on which module supplies them; this module only spares the imaging chain
the import of scipy.constants, which parses the whole CODATA table.
"""

from __future__ import annotations

C = 299_792_458.0  # speed of light in vacuum [m/s]: exact (SI 2019; CODATA 2022)
Q_E = 1.602176634e-19  # elementary charge [C]: exact (SI 2019; CODATA 2022)
H = 6.62607015e-34  # Planck constant [J s]: exact (SI 2019; CODATA 2022)
K_B = 1.380649e-23  # Boltzmann constant [J/K]: exact (SI 2019; CODATA 2022)
