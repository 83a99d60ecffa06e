"""Unit factors of dynprop's I/O boundary, defined once for the whole application.

Inside, every quantity is SI (rad, s, N m, kg m², A m², T); degrees and rpm appear
only where a file column, a scenario key or a console line names them
(``roll_deg``, ``wheel1_rpm``).  The factors are written exactly as each place
used to write its own copy, so every number in a run directory keeps its bits.
"""

import numpy as np

DEG = np.pi / 180.0               # rad per degree
RAD2DEG = 180.0 / np.pi           # degrees per rad
RADPS2RPM = 60.0 / (2.0 * np.pi)  # rpm per rad/s
RPM2RADPS = np.pi / 30.0          # rad/s per rpm
HOUR_S = 3600.0
DAY_S = 86400.0
