"""
The reduced model's former single module: names re-exported for importers not yet moved.

The reduced model now lives in :mod:`.tables` (the model), :mod:`.cells` (monomials and
splines), :mod:`.basis`, :mod:`.build`, :mod:`.periodic`, :mod:`.pipeline`, :mod:`.reference`
and :mod:`.store`; the options in core/options.py.
"""

from . import store  # noqa: F401  SHIM
from .basis import (build_basis, fit_in_w2, frozen_modes, FrozenSamples,  # noqa: F401
                    mass_weighted_pod, MODE_WEIGHT_POWER, STATIC_PIECES)  # SHIM
from .build import reduce_samples  # noqa: F401  SHIM
from .cells import (CELL_POWERS, monomial_values, MONOMIALS,  # noqa: F401
                    periodic_cell_coefficients)  # SHIM
from .periodic import PERIODIC_CHUNK, periodic_response  # noqa: F401  SHIM
from .pipeline import (build_model, fe_mechanism, frozen_samples_for,  # noqa: F401
                       modal_damping_matrix, model_for_mechanism, model_key,
                       reaction_pieces, SHAPE_POINTS_PER_ELEMENT)  # SHIM
from .reference import (REFERENCE_GRID, REFERENCE_POINT_STRIDE,  # noqa: F401
                        reference_response, REFERENCE_STEPS,
                        unreduced_revolution)  # SHIM
from .tables import (cell_groups, output_values, ReducedModel, system_blocks,  # noqa: F401
                     TableLayout)  # SHIM
from ..options import DEFAULT_SIZES, MODEL_VERSION, ModelOptions  # noqa: F401  SHIM
from ...names import JOINT_NAMES as JOINTS, OUTPUT_NAMES  # noqa: F401  SHIM
