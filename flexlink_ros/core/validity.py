"""
Validity of the linear + second-order estimate: a per-sample nonlinearity indicator.

The linear KED model (:mod:`core.fe.linkage`) stiffens each link's bending by the geometric
stiffness of the RIGID-BODY axial force F_r(x) (A.4). The geometrically exact linkage carries the
whole axial force: F_r plus the ELASTIC part N_e that the elastic vibration adds (the inertia
of the vibrating links and joint masses reacted along the links). N_e is amplitude dependent, so
it detunes the bending modes with the response itself; near a resonance that detuning decides
the amplitude, and neither the linear model nor the quasi-static second order of
:mod:`core.fe.second_order_full` (computed from the linear state) can follow it.

Elastic axial force (from the linear state only). The FE element axial force EA (u2 - u1) / l_e
(:meth:`core.fe.linkage.FlexibleLinkage.element_axial_forces`) is, for the axially stiff links
(axial modes above 2 kHz), quasi-static: the element average of the axial force the FE loads
carry. Its rigid-body part is the element average of F_r(x) (:func:`core.dynamics.axial_force`,
Gauss-averaged), so ::

    N_e = EA (u2 - u1) / l_e - (1 / l_e) int_e F_r(x) dx                            (1)

(:func:`elastic_axial_forces`). Compared with the Euler load of the pinned-pinned link ::

    P_cr = pi^2 E I / L^2                                                               (2)

(:func:`buckling_loads`: 36.3 N coupler, 43.3 N lever for cho1992), a uniform tension N shifts
the link's first bending mode by Delta(omega^2) / omega^2 = N / P_cr exactly (pinned-pinned,
sine shape), i.e. Delta omega / omega = N / (2 P_cr).

Indicator (:func:`nonlinearity_indicator`): the detuning ratio. Per sample and per reference
mode j (each flexible link's first bending mode, :func:`mode_reference`: frozen frequency omega_j
and strain-energy share s_jl of link l, revolution means at the crank speed) ::

    Delta omega_j = omega_j / 2 * sum_l s_jl N_e,l / P_cr,l
    I = max_j |Delta omega_j| / sqrt(d_j^2 + (zeta omega_j)^2)                           (3)

with N_e,l the link-mean of Eq. (1) and d_j the distance of omega_j from the nearest crank
harmonic k |w| (:func:`resonance_distance`; the half-power half-width zeta omega_j is the floor
at exact resonance). I is the amplitude-dependent frequency shift in units of the distance to
resonance: where it is small the response amplitude hardly depends on the shift, so the linear
state (and the second order computed from it) stands; where it approaches 1 the peer's resonance
has moved by about its own width and one corrective pass cannot follow it.

Choice, against the Exudyn peer (``python docs/studies/validity_study.py``, rigid crank
and bearings, no gravity, 8 elements per link, 250-450 rpm; README note for the tables). Three
candidates were computed from the linear state:

* the second-order correction against the linear output: it cannot separate for the lever tip
  (its second order is 10-70 times its linear motion at every speed with rigid bearings), and
  for the coupler mid-point it grows with speed like the response itself;
* the load ratio max |N_e| / P_cr (:func:`load_ratio_indicator`): rises through the resonance
  band (0.006 at 269 rpm, 0.07 at 405 rpm) but equally above it, where the amplitude is large
  but off resonance and linear + second order is within its targets again (425-450 rpm), and it
  is as large at the accurate 385-391 rpm as at the inaccurate 340 rpm: no threshold separates;
* the detuning ratio (3): with the linear damping matched to the peer's (zeta = 0.012) it flags
  every speed outside the targets (10 % lever tip, 3 % coupler mid-point p2p: 340-350 and
  395-420 rpm) at :data:`VALIDITY_THRESHOLD` = 0.5, with one false alarm at the band's upper
  edge (425 rpm, 0.63). Chosen. With the mechanism's default zeta = 0.02 (more damping than
  the peer's beta = 1e-4 s gives) the flag turns false at 350 and 400-420 rpm (405 rpm: 1.11;
  269 rpm: 0.10); the other speeds then off target (260, 310 rpm: weakly forced 8th-harmonic
  resonances, lever tip p2p 20-80 um; 340, 380-395, 425-430 rpm) are off because of the
  damping convention, not the nonlinearity: with zeta matched they are within the targets
  (or flagged). The indicator does not, and should not, see a damping mismatch.

Cost per sample: the link means of N_e (one row of T^T U per element end, two links) and a 2 x 2
product; omega_j, s_jl and d_j are constants per speed. The estimator evaluates it from the
reduced state (:mod:`core.reduction.nonlinearity_tables` tabulates N_e / P_cr per link as rows
on the basis, with the residual flexibility the basis misses; :mod:`core.estimation.nonlinearity`
gives ``Sample.nonlinearity``), ``simulate`` / ``estimate --json`` summarise it as
``"nonlinearity": {"indicator_max", "valid", "threshold"}`` (:func:`is_valid`), and
flexlink_node's ``/diagnostics`` estimator status WARNs above :data:`VALIDITY_THRESHOLD`.
"""

import math

import numpy as np

from .dynamics import axial_force
from .fe.link import gauss_points
from .fe.modes import frozen_mode_sweep
from .kinematics import solve_kinematics

# Links that carry the indicator (the crank is short and stiff: P_cr = 4.7 kN for cho1992).
INDICATOR_LINKS = (1, 2)

# Threshold on the detuning ratio I (Eq. 3): the frequency shift of the elastic axial force at
# half the distance to resonance. Against the peer (rigid crank and bearings, 8 elements, 250-450
# rpm, linear zeta matched at 0.012): the smallest I among the speeds outside the targets is
# 0.51 (395 rpm, lever -12 %), the largest among the speeds within them 0.63 (425 rpm, at the
# band's upper edge: the one false alarm), the next 0.39; 269 rpm gives 0.13, 405 rpm 1.9. With
# the default zeta = 0.02: 269 rpm 0.10, 405 rpm 1.11, flagged 350 and 400-420 rpm.
VALIDITY_THRESHOLD = 0.5
# Frozen modes of the detuning ratio (each flexible link's first bending mode, rigid crank).
REFERENCE_MODES = 2
# Below this crank speed [rad/s] the harmonics are dense: the distance to resonance is its floor
# zeta omega (and omega / speed stays a finite number to round).
REST_SPEED = 1e-6


def buckling_loads(mechanism, links=INDICATOR_LINKS):
    """
    Euler buckling load of each pinned-pinned link, P_cr = pi^2 E I / L^2 [N] (Eq. 2).

    Parameters
    ----------
    mechanism : Mechanism
        With material and section data (``is_flexible``).
    links : iterable of int
        Link indices (0 crank, 1 coupler, 2 lever).

    Returns
    -------
    dict of int to float

    """
    out = {}
    for link in links:
        spec = mechanism.links[link]
        if spec.second_moment is None or mechanism.youngs_modulus is None:
            raise ValueError(f'link {link} has no bending stiffness (E I) in the mechanism')
        out[link] = math.pi ** 2 * mechanism.youngs_modulus * spec.second_moment \
            / spec.length ** 2
    return out


def rigid_element_axial_forces(linkage, crank_angle, speed, accel=0.0):
    """
    Element averages of the rigid-body axial force F_r(x) of every modelled link [N].

    The Gauss average over each element of :func:`core.dynamics.axial_force` at crank speed
    ``speed`` [rad/s] and acceleration ``accel`` [rad/s^2], with the linkage's own gravity
    setting (its mechanism has gravity zeroed when the model leaves gravity out).

    Returns
    -------
    dict of int to ndarray, shape (N, e)

    """
    theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
    mech = linkage.mechanism
    state = solve_kinematics(mech, theta, speed, accel)
    out = {}
    for link in linkage.links:
        x = linkage.gauss_positions(link)
        _, weights = gauss_points(linkage.link_matrices[link].element_length)
        values = np.asarray(axial_force(mech, state, link, x.ravel()), dtype=float)
        values = values.reshape(theta.shape[0], *x.shape)
        out[link] = values @ weights / weights.sum()
    return out


def elastic_axial_forces(linkage, displacement, crank_angle, speed, accel=0.0):
    """
    Elastic axial force N_e of every element (Eq. 1), tension > 0 [N].

    Parameters
    ----------
    linkage : FlexibleLinkage
        The model the state belongs to.
    displacement : ndarray, shape (N, n)
        Linear nodal vectors U (e.g. ``PeriodicResponse.displacement``).
    crank_angle : ndarray, shape (N,)
        Crank angles [rad] of the samples.
    speed, accel : float
        Crank speed [rad/s] and acceleration [rad/s^2] of the rigid-body motion.

    Returns
    -------
    dict of int to ndarray, shape (N, e)

    """
    total = linkage.element_axial_forces(displacement, crank_angle)
    rigid = rigid_element_axial_forces(linkage, crank_angle, speed, accel)
    return {link: total[link] - rigid[link] for link in total}


def load_ratios(linkage, displacement, crank_angle, speed, accel=0.0):
    """
    Link-mean elastic axial force over the Euler load, N_e / P_cr, per flexible link (signed).

    Returns
    -------
    dict of int to ndarray, shape (N,)
        For the links of :data:`INDICATOR_LINKS` that the linkage models.

    """
    forces = elastic_axial_forces(linkage, displacement, crank_angle, speed, accel)
    links = [link for link in INDICATOR_LINKS if link in forces]
    loads = buckling_loads(linkage.mechanism, links)
    return {link: forces[link].mean(axis=1) / loads[link] for link in links}


def load_ratio_indicator(linkage, displacement, crank_angle, speed, accel=0.0):
    """
    Candidate indicator (not the chosen one): max_link |N_e| / P_cr per sample.

    Returns
    -------
    ndarray, shape (N,)

    """
    ratios = load_ratios(linkage, displacement, crank_angle, speed, accel)
    return np.max(np.abs(np.stack(list(ratios.values()))), axis=0)


def mode_reference(linkage, speed, modes=REFERENCE_MODES, angles=12):
    """
    Frozen frequencies and per-link strain-energy shares at a crank speed, revolution means.

    Parameters
    ----------
    linkage : FlexibleLinkage
        The flexible model.
    speed : float
        Crank speed [rad/s] (the rigid-body axial forces in K_G).
    modes : int
        Lowest frozen modes kept: each link's FIRST bending mode (Eq. 2 holds for it; the n-th
        pinned-pinned mode shifts by N / (n^2 P_cr)); 2 for a rigid crank (cho1992: the 34.5 Hz
        coupler and 41.7 Hz lever modes).
    angles : int
        Crank angles of the average.

    Returns
    -------
    dict
        'omega' (modes,) [rad/s], 'share' (modes, 3) strain-energy share of crank, coupler,
        lever, 'speed' [rad/s].

    """
    grid = np.linspace(0.0, 2.0 * np.pi, angles, endpoint=False)
    frozen = frozen_mode_sweep(linkage, grid, count=modes, speed=speed)
    return {'omega': frozen.omega.mean(axis=0),
            'share': frozen.strain_share[..., :3].mean(axis=0), 'speed': float(speed)}


def resonance_distance(reference, zeta):
    """
    Distance of each reference mode from resonance, sqrt(d_j^2 + (zeta omega_j)^2) [rad/s].

    d_j is the distance of omega_j from the nearest crank harmonic k |speed| (k >= 1),
    zeta omega_j the half-power half-width.

    Parameters
    ----------
    reference : dict
        :func:`mode_reference` at the speed.
    zeta : float
        Modal damping ratio.

    Returns
    -------
    ndarray, shape (modes,)
        The distances.

    """
    omega, rate = reference['omega'], abs(reference['speed'])
    harmonic = np.maximum(np.round(omega / rate), 1.0) * rate
    return np.hypot(omega - harmonic, zeta * omega)


def detuning_ratio(omega, share, ratios, speed, zeta):
    """
    Return the detuning ratio max_j |Delta omega_j| / sqrt(d_j^2 + (zeta omega_j)^2) (Eq. 3).

    Delta omega_j = omega_j / 2 sum_l s_jl N_e,l / P_cr,l; d_j the distance of omega_j from the
    nearest crank harmonic k |speed| (k >= 1; d_j = 0 below :data:`REST_SPEED`), as
    :func:`resonance_distance`.

    Parameters
    ----------
    omega : ndarray, shape (..., modes)
        Reference frequencies [rad/s].
    share : ndarray, shape (..., modes, links)
        Strain-energy shares of the links.
    ratios : ndarray, shape (..., links)
        Link-mean elastic axial force over the Euler load.
    speed : ndarray, shape (...)
        Crank speed [rad/s] (its magnitude sets the harmonics).
    zeta : float
        Modal damping ratio.

    Returns
    -------
    ndarray, shape (...)

    """
    shift = 0.5 * omega * np.einsum('...jl,...l->...j', share, ratios)
    rate = np.abs(np.asarray(speed, dtype=float))[..., None]
    moving = rate > REST_SPEED
    safe = np.where(moving, rate, 1.0)
    harmonic = np.where(moving, np.maximum(np.round(omega / safe), 1.0) * safe, omega)
    return np.max(np.abs(shift) / np.hypot(omega - harmonic, zeta * omega), axis=-1)


def nonlinearity_indicator(linkage, displacement, crank_angle, speed, zeta=None,
                           reference=None, accel=0.0):
    """
    Per-sample detuning ratio (Eq. 3), dimensionless: the chosen validity indicator.

    For each reference mode j, the shift the elastic axial forces cause,
    Delta omega_j = omega_j / 2 sum_l s_jl N_e,l / P_cr,l (Eq. 2 weighted by the link's
    strain-energy share s_jl), against :func:`resonance_distance`; the maximum over j.

    Parameters
    ----------
    linkage : FlexibleLinkage
        The flexible model.
    displacement : ndarray, shape (N, n)
        Linear nodal vectors U.
    crank_angle : ndarray, shape (N,)
        Crank angles [rad] of the samples.
    speed : float
        Crank speed [rad/s].
    zeta : float or None
        Modal damping ratio of the model (None: ``mechanism.damping_ratio``).
    reference : dict or None
        :func:`mode_reference` at this speed (computed when None; precompute it per speed to
        evaluate samples cheaply).

    accel : float
        Crank acceleration [rad/s^2] of the rigid-body motion.

    Returns
    -------
    ndarray, shape (N,)

    """
    zeta = linkage.mechanism.damping_ratio if zeta is None else float(zeta)
    reference = mode_reference(linkage, speed) if reference is None else reference
    ratios = load_ratios(linkage, displacement, crank_angle, speed, accel)
    links = list(ratios)
    return detuning_ratio(reference['omega'], reference['share'][:, links],
                          np.stack([ratios[link] for link in links], axis=-1), speed, zeta)


def is_valid(indicator, threshold=VALIDITY_THRESHOLD):
    """
    Summary of a revolution (or any run): the ``"nonlinearity"`` entry of the JSON outputs.

    ``{'indicator_max': float, 'valid': bool, 'threshold': float}`` over the finite values of
    ``indicator`` (``simulate`` / ``estimate --json``); with no finite value (a model without
    the indicator's tables) 'indicator_max' and 'valid' are None.
    """
    values = np.asarray(indicator, dtype=float).ravel()
    values = values[np.isfinite(values)]
    if not values.size:
        return {'indicator_max': None, 'valid': None, 'threshold': float(threshold)}
    peak = float(np.max(values))
    return {'indicator_max': peak, 'valid': bool(peak <= threshold),
            'threshold': float(threshold)}


__all__ = ['INDICATOR_LINKS', 'REFERENCE_MODES', 'REST_SPEED', 'VALIDITY_THRESHOLD',
           'buckling_loads', 'rigid_element_axial_forces', 'elastic_axial_forces', 'load_ratios',
           'load_ratio_indicator', 'mode_reference', 'resonance_distance',
           'detuning_ratio', 'nonlinearity_indicator', 'is_valid']
