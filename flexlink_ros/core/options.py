"""Modelling options shared by the FE assembly, the reduced model, the node and the CLI."""

import dataclasses
import math

MODEL_VERSION = 3
# Default (modes, static) per (bearing model, rigid crank), from flexlink plan on Cho 1992
# with geometric stiffness, 269 and 391 rpm. Rigid crank: the smallest sizes meeting 1 % on
# the coupler mid-point against that model's own full order (flexible bearings put the
# 5th-7th crank harmonics on the first two modes, which a constant basis must resolve to a
# fraction of zeta; 12 + 4 gave 1.7 % at 391 rpm, 14 + 4 1.1 %, 16 + 2 0.4 %). Flexible
# crank: the crank-dominated mode (72-127 Hz over the cycle) needs far more directions;
# 24 + 2 at grid 128 and 4 elements gives 1.3 % / 0.9 % (coupler / lever) against a
# 6-element reference, 16 + 4 gave 16 %; with rigid bearings 8 + 4 at grid 256 gives 0.9 %.
DEFAULT_SIZES = {('rigid', True): (4, 2), ('flexible', True): (16, 2),
                 ('rigid', False): (8, 4), ('flexible', False): (24, 2)}
# The default model meets this relative RMS error on Cho 1992 against flexlink plan's scene
# reference (1.3 % coupler, 0.9 % lever): the node warns when asked for less.
PLANNED_TOLERANCE = 0.02
# Default (modes, static) with the dynamic second-order pass: the second-order motion needs
# more directions than the linear one (rigid crank, rigid bearings, 391 rpm against the peer:
# the coupler mid-point +5.0 % p2p with the pass on 4 + 2, +0.6 % on 8 + 4). Measured for
# that case only; elsewhere the linear sizes with at least 8 modes and 4 static directions.
DYNAMIC_SIZES = {key: (max(modes, 8), max(static, 4)) for key, (modes, static)
                 in DEFAULT_SIZES.items()}
SECOND_ORDER_PASSES = ('quasi-static', 'dynamic')
# The model's speed range [rad/s] when the mechanism file states no crank speed (620 rpm).
DEFAULT_SPEED_MAX = 65.0
# Margin of the speed range over a file's crank_speed_rpm: a crank runs up and overshoots its
# nominal speed; beyond the range the model sees the clipped speed (flagged and logged).
SPEED_MARGIN = 1.25


@dataclasses.dataclass(frozen=True)
class ModelOptions:
    """
    Modelling choices: the frozen structure (FE) and the reduced model built from it.

    One set of options from the node's parameters or the CLI's flags down to the assembly.
    The defaults are THE default model, defined here only: the node's parameters, every
    command's flags and the benches take theirs from them (flexible crank of 4 elements per
    link, flexible bearings, geometric stiffness, second-order outputs). :meth:`full_model`
    gives the full-order studies' model (flexible crank, pinned bearings, the file's
    elements, order 1) and :meth:`linear` the paper's linear KED with a rigid
    crank, on which the unit tests and studies are measured. Every field is part
    of the reduced model's cache key (:meth:`cache_fields`; ``gravity`` only when it is off
    and ``stiffness_damping`` only when it is not 0, so the default model keeps its key).

    Parameters
    ----------
    modes : int or None
        Basis directions from the frozen modes (None: :data:`DEFAULT_SIZES` for the bearings
        and the crank model).
    static : int or None
        Further basis directions from static load responses (None: as ``modes``).
    grid_size : int
        Crank-angle grid points per revolution.
    elements_per_link : int or None
        Beam elements per link of the full model (None: the mechanism file's value; the
        default 4 is what the flexible crank's default sizes were planned with).
    rigid_crank : bool
        Treat the crank as rigid.
    bearings : str
        'flexible' (springs of the mechanism file) or 'rigid'.
    geometric_stiffness : bool
        Include the geometric stiffness of the rigid-body axial forces.
    speed_max : float
        Largest |crank speed| served [rad/s] (:func:`speed_range`: from the mechanism file's
        crank speed with :data:`SPEED_MARGIN`, at least :data:`DEFAULT_SPEED_MAX`).
    gravity : bool
        Include gravity (``mechanism.gravity``) in loads and axial forces.
    stiffness_damping : float
        Stiffness-proportional (Kelvin-Voigt) damping beta [s] on the link-frame strain rates
        and c = beta k on the bearing springs (:mod:`core.fe.stiffness_damping`), on top of
        the mechanism's modal ``damping_ratio``; 0 leaves it out. Part of the cache key only
        when non-zero, so the keys of models without it stay as they were.
    order : int
        1: the linear KED outputs of the paper; 2: plus the second-order motion of the bent
        links' chord shortening (core/fe/second_order_*.py; the reduced model then carries its
        tables).
    soft_modes : int
        The estimator's second reduction onto the p lowest modes (core/reduction/soft_basis.py):
        -1 (default) the smallest p at a usable spectral gap, or all r coordinates where the
        model has none (recorded in ``info['soft']``); p > 0 exactly p (refused without a gap
        there); 0 steps all r coordinates (so does the dynamic second-order pass). Not part
        of the cache key: the soft tables are made from the cached model when it is loaded.
    second_order : str
        At order 2, 'quasi-static' (the chord shortening of the linear state's shapes) or
        'dynamic': also the dynamic second-order pass in the streaming step (a second reduced
        state loaded by the second-order terms of the strain energy,
        core/estimation/second_order_dynamic_step.py; its tables are part of the model), with
        :data:`DYNAMIC_SIZES` when ``modes`` / ``static`` are None. Part of the cache key
        only when 'dynamic'.

    """

    modes: object = None
    static: object = None
    grid_size: int = 128
    elements_per_link: object = 4
    rigid_crank: bool = False
    bearings: str = 'flexible'
    geometric_stiffness: bool = True
    speed_max: float = DEFAULT_SPEED_MAX
    gravity: bool = True
    stiffness_damping: float = 0.0
    order: int = 2
    soft_modes: int = -1
    second_order: str = 'quasi-static'

    def __post_init__(self):
        if self.bearings not in ('flexible', 'rigid'):
            raise ValueError(f"`bearings` must be 'flexible' or 'rigid', got {self.bearings!r}")
        if self.second_order not in SECOND_ORDER_PASSES:
            raise ValueError(f'`second_order` must be one of {SECOND_ORDER_PASSES}, got '
                             f'{self.second_order!r}')
        if self.second_order == 'dynamic' and self.order != 2:
            raise ValueError("`second_order` 'dynamic' needs `order` 2 (it keeps the "
                             'quasi-static correction and adds the dynamic increment)')
        sizes = DYNAMIC_SIZES if self.second_order == 'dynamic' else DEFAULT_SIZES
        modes, static = sizes[self.bearings, bool(self.rigid_crank)]
        object.__setattr__(self, 'modes', modes if self.modes is None else int(self.modes))
        object.__setattr__(self, 'static', static if self.static is None else int(self.static))
        if self.modes < 1 or self.static < 0:
            raise ValueError(f'`modes` must be >= 1 and `static` >= 0, got {self.modes}, '
                             f'{self.static}')
        if self.grid_size < 8:
            raise ValueError(f'`grid_size` must be >= 8, got {self.grid_size}')
        if self.order not in (1, 2):
            raise ValueError(f'`order` must be 1 or 2, got {self.order!r}')
        if int(self.soft_modes) < -1:
            raise ValueError(f'`soft_modes` must be -1, 0 or positive, got {self.soft_modes}')
        object.__setattr__(self, 'soft_modes', int(self.soft_modes))
        if not self.speed_max > 0.0:
            raise ValueError(f'`speed_max` must be positive, got {self.speed_max}')
        beta = float(self.stiffness_damping)
        if not (math.isfinite(beta) and beta >= 0.0):
            raise ValueError(f'`stiffness_damping` must be >= 0 [s], got {beta}')
        object.__setattr__(self, 'stiffness_damping', beta)

    @classmethod
    def full_model(cls, **changes):
        """Options of the full-order studies: flexible crank, pinned bearings, file's elements."""
        return cls(**{'rigid_crank': False, 'bearings': 'rigid', 'elements_per_link': None,
                      'order': 1, **changes})

    @classmethod
    def linear(cls, **changes):
        """Options of the paper's linear KED with a rigid crank on the file's elements."""
        return cls(**{'rigid_crank': True, 'elements_per_link': None, 'order': 1, **changes})

    def cache_fields(self):
        """
        Return the fields identifying a reduced model, in declaration order.

        ``gravity`` is left out when it is on, ``stiffness_damping`` when it is 0, ``order``
        when it is 1 and ``second_order`` when it is 'quasi-static', so a default model keeps
        the key it had before these fields existed (its cache files still load); a model built
        without gravity has loads of its own, and one of order 2 (or with the dynamic pass)
        carries extra tables, so none may share that key.
        """
        fields = dataclasses.asdict(self)
        del fields['soft_modes']
        if fields['gravity']:
            del fields['gravity']
        if not fields['stiffness_damping']:
            del fields['stiffness_damping']
        if self.order == 1:
            del fields['order']
        if self.second_order == 'quasi-static':
            del fields['second_order']
        return fields


def speed_range(crank_speed=None, speed_max_rpm=0.0):
    """
    Return the model's speed range [rad/s]: the one asked for, else the file's with a margin.

    Parameters
    ----------
    crank_speed : float or None
        The mechanism file's nominal crank speed [rad/s] (``crank_speed_rpm``), if any.
    speed_max_rpm : float
        A range asked for [rpm] (the node's ``model.speed_max_rpm``, the plan's
        ``--rpm-max``); 0: :data:`SPEED_MARGIN` times the file's crank speed, at least
        :data:`DEFAULT_SPEED_MAX` (so a file without a crank speed keeps the default model).

    """
    if speed_max_rpm and speed_max_rpm > 0.0:
        return float(speed_max_rpm) * math.pi / 30.0
    if crank_speed:
        return max(DEFAULT_SPEED_MAX, SPEED_MARGIN * abs(float(crank_speed)))
    return DEFAULT_SPEED_MAX
