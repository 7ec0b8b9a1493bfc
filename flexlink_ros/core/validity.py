"""
Validity of the linear + second-order estimate: a per-sample nonlinearity indicator (issue 14).

The linear KED model (:mod:`core.assembly`) stiffens each link's bending by the geometric
stiffness of the RIGID-BODY axial force F_r(x) (A.4). The geometrically exact linkage carries the
whole axial force: F_r plus the ELASTIC part N_e that the elastic vibration adds (the inertia
of the vibrating links and joint masses reacted along the links). N_e is amplitude dependent, so
it detunes the bending modes with the response itself; near a resonance that detuning decides
the amplitude, and neither the linear model nor the quasi-static second order of
:mod:`core.second_order` (computed from the linear state) can follow it.

Elastic axial force (from the linear state only). The FE element axial force EA (u2 - u1) / l_e
(:meth:`core.assembly.FlexibleLinkage.element_axial_forces`) is, for the axially stiff links
(axial modes above 2 kHz), quasi-static: the element average of the axial force the FE loads
carry. Its rigid-body part is the element average of F_r(x) (:func:`core.dynamics.axial_force`,
Gauss-averaged), so ::

    N_e = EA (u2 - u1) / l_e - (1 / l_e) int_e F_r(x) dx                            (1)

(:func:`elastic_axial_forces`). Compared with the Euler load of the pinned-pinned link ::

    P_cr = pi^2 E I / L^2                                                               (2)

(:func:`buckling_loads`: 36.3 N coupler, 43.3 N lever for cho1992), a uniform tension N shifts
the link's first bending mode by Delta(omega^2) / omega^2 = N / P_cr exactly (pinned-pinned,
sine shape), i.e. Delta omega / omega = N / (2 P_cr).

Indicator (:func:`nonlinearity_indicator`). Per sample ::

    I = max over the two flexible links of |N_e, link-mean| / P_cr,link                  (3)

the link-mean of N_e over its elements. Two other candidates were measured against the Exudyn
peer over 250-450 rpm (rigid crank, rigid bearings, no gravity, 8 elements per link;
``python -m flexlink_ros.studies.validity_study``): the detuning ratio
:func:`detuning_ratio` (the frequency shift (3) causes in each frozen mode against that mode's
distance from the nearest crank harmonic, with the half-power half-width zeta omega as a floor)
and the second-order correction against the linear output. The second-order ratio does not
separate (with rigid bearings the lever tip's second order is 10-70 times its linear motion at
every speed). The detuning ratio and (3) both separate the resonance band; (3) is chosen
because it needs nothing but the linear state (no frozen modes, no damping assumption, no
harmonic bookkeeping), costs one dot product per link per sample, and separated the measured
sweep at least as cleanly (see :data:`VALIDITY_THRESHOLD`).
"""

import dataclasses
import math

import numpy as np

from .assembly import gauss_points
from .dynamics import axial_force
from .kinematics import solve_kinematics

# Links that carry the indicator (the crank is short and stiff: P_cr = 4.7 kN for cho1992).
INDICATOR_LINKS = (1, 2)

# Threshold on I = max |N_e| / P_cr (Eq. 3) over a revolution. Justification (sweep of
# studies/validity_study.py against the Exudyn peer, rigid crank and bearings, no gravity,
# 8 elements per link): see the README note; filled in from the measured table.
VALIDITY_THRESHOLD = 0.03


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


def nonlinearity_indicator(linkage, displacement, crank_angle, speed, accel=0.0):
    """
    Per-sample nonlinearity indicator I = max_link |N_e| / P_cr (Eq. 3), dimensionless.

    The linear + second-order estimate is trusted where I stays below
    :data:`VALIDITY_THRESHOLD` (:func:`is_valid`).

    Returns
    -------
    ndarray, shape (N,)

    """
    ratios = load_ratios(linkage, displacement, crank_angle, speed, accel)
    return np.max(np.abs(np.stack(list(ratios.values()))), axis=0)


def is_valid(indicator, threshold=VALIDITY_THRESHOLD):
    """
    Summary of a revolution (or any run): {'indicator_max': float, 'valid': bool}.

    The form of the ``"nonlinearity"`` entry of ``simulate`` / ``estimate --json``.
    """
    peak = float(np.max(indicator)) if np.size(indicator) else 0.0
    return {'indicator_max': peak, 'valid': bool(peak <= threshold)}


def detuning_ratio(linkage, displacement, crank_angle, speed, zeta, modes=4, angles=12):
    """
    Candidate indicator (not the chosen one): frequency shift against distance from resonance.

    For each of the lowest ``modes`` frozen modes j (averaged over ``angles`` crank angles:
    omega_j and its strain-energy share s_jl per link), the shift the elastic axial force
    causes, Delta omega_j = omega_j / 2 sum_l s_jl N_e,l / P_cr,l (Eq. 2's pinned-pinned
    result weighted by the link's share), against sqrt(d_j^2 + (zeta omega_j)^2), d_j the
    distance of omega_j from the nearest crank harmonic k |speed| (k >= 1).

    Returns
    -------
    ndarray, shape (N,)
        max over j of |Delta omega_j| / sqrt(d_j^2 + (zeta omega_j)^2).

    """
    from .modes import frozen_mode_sweep
    grid = np.linspace(0.0, 2.0 * np.pi, angles, endpoint=False)
    frozen = frozen_mode_sweep(linkage, grid, count=modes, speed=speed)
    omega = frozen.omega.mean(axis=0)
    share = frozen.strain_share[..., :3].mean(axis=0)                  # (modes, 3)
    ratios = load_ratios(linkage, displacement, crank_angle, speed)
    rel = sum(share[None, :, link] * ratios[link][:, None] for link in ratios)   # (N, modes)
    shift = 0.5 * omega[None, :] * rel
    rate = abs(speed)
    harmonic = np.maximum(np.round(omega / rate), 1.0) * rate
    distance = np.hypot(omega - harmonic, zeta * omega)
    return np.max(np.abs(shift) / distance[None, :], axis=1)


__all__ = ['INDICATOR_LINKS', 'VALIDITY_THRESHOLD', 'buckling_loads',
           'rigid_element_axial_forces', 'elastic_axial_forces', 'load_ratios',
           'nonlinearity_indicator', 'is_valid', 'detuning_ratio']
