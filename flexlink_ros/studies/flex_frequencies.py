"""
The frequency cases of Cho, Park & Lee (1992), Figs. 7-13, and their frozen-mode sweeps.

The paper's cases are :class:`FrequencyCase` values (:func:`paper_frequency_cases`);
:func:`sweep_case` solves one over the crank angle and finds its mode events
(:mod:`studies.flex_events`). :func:`quasi_static_axial_force` is the paper's source of the
axial loads in K_G.
"""

import dataclasses

import numpy as np

from .flex_events import detect_mode_events, refine_mode_event
from ..core.fe.linkage import FlexibleLinkage
from ..core.fe.modes import solve_frozen_modes
from ..core.options import ModelOptions

# Crank speeds of the paper's frequency plots [rad/s] (Figs. 8-13) and deflection plots [rpm].
PAPER_SPEEDS_RAD_S = (30.0, 45.0)
PAPER_RPM = (269.0, 391.0)
# The paper's mode-shape angles [deg] (Figs. 14-15) and bearing models (Figs. 20-21).
SHAPE_ANGLES_DEG = (27.0, 123.0)
BEARINGS = ('rigid', 'flexible')


def quasi_static_axial_force(mechanism, state, link, x):
    """
    Axial force [N] of a link from the FE quasi-static solution K U = R (tension > 0).

    The paper obtains its axial loads this way ("by a quasi-static displacement analysis",
    Conclusion 1 of Cho 1992); the rigid-body analysis (``core.dynamics.axial_force``) gives
    the same element means (test_assembly). Same signature as ``core.dynamics.axial_force``,
    so it can stand in for it; the force is constant over each element (A.4 as printed).

    Parameters
    ----------
    mechanism : Mechanism
        The linkage.
    state : LinkageState
        Rigid-body state at N crank angles (crank speed ``state.omega[0]``, acceleration
        ``state.alpha[0]``).
    link : int
        Link index (0 crank, 1 coupler, 2 lever).
    x : ndarray, shape (m,)
        Positions along the link [m].

    Returns
    -------
    ndarray, shape (N, m)

    """
    model = FlexibleLinkage(mechanism, ModelOptions.full_model(geometric_stiffness=False))
    theta = np.atleast_1d(state.angle[0])
    system = model.assemble(theta)
    speed = np.broadcast_to(np.asarray(state.omega[0], dtype=float), theta.shape)
    accel = np.broadcast_to(np.asarray(state.alpha[0], dtype=float), theta.shape)
    load = (system.load['1'] + accel[:, None] * system.load['a']
            + (speed * speed)[:, None] * system.load['w2'])
    displacement = np.linalg.solve(system.stiffness, load[..., None])[..., 0]
    forces = model.element_axial_forces(displacement, theta)[link]
    length = model.link_matrices[link].element_length
    element = np.minimum((np.asarray(x, dtype=float) / length).astype(int), forces.shape[1] - 1)
    return forces[:, element]


@dataclasses.dataclass(frozen=True)
class FrequencyCase:
    """
    One curve family of the paper's frequency plots.

    Attributes
    ----------
    key : str
        Short identifier.
    label : str
        Legend text.
    options : ModelOptions
    speed_rad_s : float
        Crank speed of the axial forces in K_G [rad/s] (irrelevant without K_G).

    """

    key: str
    label: str
    options: ModelOptions
    speed_rad_s: float = 0.0


def paper_frequency_cases():
    """
    Return the cases of Figs. 7-13 of Cho 1992 (bearings rigid unless named).

    The speed-free cases without geometric stiffness, and the K_G cases at 30 and 45 rad/s.

    Returns
    -------
    dict of str to FrequencyCase

    """
    cases = [
        FrequencyCase('flex', 'all flexible, no K_G',
                      ModelOptions.full_model(geometric_stiffness=False)),
        FrequencyCase('rigid_crank', 'rigid crank, no K_G',
                      ModelOptions.full_model(rigid_crank=True, geometric_stiffness=False)),
        FrequencyCase('rigid_crank_bearings', 'rigid crank, flexible bearings, no K_G',
                      ModelOptions.full_model(rigid_crank=True, bearings='flexible',
                                              geometric_stiffness=False)),
    ]
    for speed in PAPER_SPEEDS_RAD_S:
        tag = f'{speed:g} rad/s'
        cases += [
            FrequencyCase(f'flex_kg_{speed:g}', f'all flexible, K_G at {tag}',
                          ModelOptions.full_model(), speed),
            FrequencyCase(f'rigid_crank_kg_{speed:g}', f'rigid crank, K_G at {tag}',
                          ModelOptions.full_model(rigid_crank=True), speed),
            FrequencyCase(f'rigid_crank_bearings_kg_{speed:g}',
                          f'rigid crank, flexible bearings, K_G at {tag}',
                          ModelOptions.full_model(rigid_crank=True, bearings='flexible'),
                          speed),
        ]
    return {case.key: case for case in cases}


@dataclasses.dataclass(frozen=True)
class Sweep:
    """
    Frozen modes of one case over crank angles.

    Attributes
    ----------
    case : FrequencyCase
    crank_deg : ndarray, shape (N,)
    frequencies_hz : ndarray, shape (N, m)
    shapes : ndarray, shape (N, n, m)
        Mass-normalised mode shapes.
    mass : ndarray, shape (N, n, n)
    dominant_link : ndarray of int, shape (N, m)
        Link with the largest strain-energy share (0 crank, 1 coupler, 2 lever).
    strain_share : ndarray, shape (N, m, 4)
        Crank, coupler, lever, springs.
    events : list of ModeEvent
        Veerings and swaps over the cycle (:func:`detect_mode_events`, periodic).

    """

    case: FrequencyCase
    crank_deg: np.ndarray
    frequencies_hz: np.ndarray
    shapes: np.ndarray
    mass: np.ndarray
    dominant_link: np.ndarray
    strain_share: np.ndarray
    events: list


def sweep_case(mechanism, case, crank_deg, count=3):
    """
    Frozen eigen-analysis of a case over crank angles, with its mode events.

    One extra mode is solved so that the event detector sees the neighbour of the highest
    requested mode; it is not returned.

    Parameters
    ----------
    mechanism : Mechanism
        The linkage.
    case : FrequencyCase
        Model options and speed of the axial forces.
    crank_deg : ndarray, shape (N,)
        Crank angles [deg]; a full turn (equal steps) is treated as periodic.
    count : int
        Modes returned.

    Returns
    -------
    Sweep

    """
    crank_deg = np.asarray(crank_deg, dtype=float)
    model = FlexibleLinkage(mechanism, case.options)
    system = model.assemble(np.radians(crank_deg))
    solved = min(count + 1, model.size)
    frozen = solve_frozen_modes(system, solved, case.speed_rad_s)
    steps = np.diff(crank_deg)
    periodic = bool(len(crank_deg) > 2 and np.allclose(steps, steps[0])
                    and np.isclose(crank_deg[-1] + steps[0] - crank_deg[0], 360.0))
    events = [refine_mode_event(model, case.speed_rad_s, e, steps[0] if len(steps) else 1.0)
              for e in detect_mode_events(crank_deg, frozen.frequencies_hz, frozen.shapes,
                                          system.mass, periodic=periodic)
              if max(e.modes) < count]
    keep = slice(0, count)
    return Sweep(case=case, crank_deg=crank_deg, frequencies_hz=frozen.frequencies_hz[:, keep],
                 shapes=frozen.shapes[:, :, keep], mass=system.mass,
                 dominant_link=frozen.dominant_link[:, keep],
                 strain_share=frozen.strain_share[:, keep], events=events)


__all__ = ['PAPER_SPEEDS_RAD_S', 'PAPER_RPM', 'SHAPE_ANGLES_DEG', 'BEARINGS',
           'quasi_static_axial_force', 'FrequencyCase',
           'paper_frequency_cases', 'Sweep', 'sweep_case']
