"""
Former home of the transfer-matrix beam frequencies of Kim & Moon, now split by concept.

:mod:`core.tmm.beams` (uniform and lumped beams, mass lumping), :mod:`core.tmm.matrices`
(transfer matrices and |D(omega)|), :mod:`core.tmm.roots` (scan and refinement of the roots),
:mod:`core.tmm.solve` (:func:`tmm_frequencies`), :mod:`core.tmm.eigen` (stiffness-based
references) and :mod:`core.tmm.exact` (continuous beam). The names below are re-exported for
importers not yet pointed at those modules.
"""

from .beams import BOUNDARY_CONDITIONS, check_boundary_condition  # noqa: F401  SHIM
from .beams import KIM_MOON_GRAVITY, lump_masses, LumpedBeam, LUMPING_METHODS  # noqa: F401  SHIM
from .beams import STANDARD_GRAVITY, UniformBeam  # noqa: F401  SHIM
from .eigen import DENSE_EIGEN_LIMIT, fe_frequencies, lumped_frequencies  # noqa: F401  SHIM
from .exact import exact_beta_l, exact_frequencies  # noqa: F401  SHIM
from .matrices import determinant_to_kgf_mm, field_matrix  # noqa: F401  SHIM
from .matrices import frequency_determinant, frequency_determinants  # noqa: F401  SHIM
from .matrices import point_matrix  # noqa: F401  SHIM
from .roots import available_modes, DEFAULT_DTOL, DEFAULT_RTOL  # noqa: F401  SHIM
from .roots import DEFAULT_STEP_RAD_S, MAX_ITERATIONS, MAX_SCAN_STEPS  # noqa: F401  SHIM
from .roots import PAPER_DETERMINANT_TOL, refine_root, RootResult  # noqa: F401  SHIM
from .roots import scan_brackets, SEARCHES  # noqa: F401  SHIM
from .solve import tmm_frequencies, TmmResult, VERIFY_RTOL  # noqa: F401  SHIM
