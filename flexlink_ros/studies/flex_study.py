"""
Former home of the flexible four-bar studies, now in their own modules.

:mod:`studies.flex_frequencies` (the paper's cases and sweeps), :mod:`studies.flex_events`
(mode veering and swaps), :mod:`studies.flex_truncation` (modal truncation) and
:mod:`studies.flex_measures` (measures for the paper's claims).
"""

from .flex_events import detect_mode_events, mac, ModeEvent, refine_mode_event  # noqa: F401  SHIM
from .flex_frequencies import FrequencyCase, paper_frequency_cases  # noqa: F401  SHIM
from .flex_frequencies import PAPER_RPM, PAPER_SPEEDS_RAD_S  # noqa: F401  SHIM
from .flex_frequencies import quasi_static_axial_force, Sweep, sweep_case  # noqa: F401  SHIM
from .flex_measures import bending_deflection, harmonic_shares  # noqa: F401  SHIM
from .flex_measures import shape_correlation, signed_area  # noqa: F401  SHIM
from .flex_measures import uniform_load_shape  # noqa: F401  SHIM
from .flex_truncation import modes_needed, output_errors, OUTPUT_POINTS  # noqa: F401  SHIM
from .flex_truncation import TOLERANCES, truncation_study  # noqa: F401  SHIM
