"""
Former home of the second-order motion (issue 14), now split by concept.

:mod:`core.fe.second_order_geometry` (chord shortening and loop closure, Eqs. 1-4),
:mod:`core.fe.second_order_full` (from full-order nodal vectors) and
:mod:`core.fe.second_order_reduced` (quadratic forms on a reduced basis). The names below are
re-exported for importers not yet pointed at those modules.
"""

from .second_order_full import bending_sums, corrected_response, link_forms  # noqa: F401  SHIM
from .second_order_full import link_local, LinkForms, second_order_outputs  # noqa: F401  SHIM
from .second_order_geometry import bending_integral, chord_shortening  # noqa: F401  SHIM
from .second_order_geometry import coupler_point_second_order, FORMS  # noqa: F401  SHIM
from .second_order_geometry import loop_closure_second_order  # noqa: F401  SHIM
from .second_order_geometry import output_coefficients  # noqa: F401  SHIM
from .second_order_geometry import unit_geometric_stiffness  # noqa: F401  SHIM
from .second_order_reduced import factored_forms, factored_second_order  # noqa: F401  SHIM
from .second_order_reduced import FactoredForms, form_matrices  # noqa: F401  SHIM
from .second_order_reduced import gather_harmonics, harmonic_matrices  # noqa: F401  SHIM
from .second_order_reduced import quadratic_tables, reduced_second_order  # noqa: F401  SHIM
from .second_order_reduced import step_cost  # noqa: F401  SHIM
from ...names import OUTPUT_NAMES  # noqa: F401  SHIM
