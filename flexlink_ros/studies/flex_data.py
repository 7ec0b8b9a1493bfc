"""
Every number of the flexible four-bar report section (Cho, Park & Lee 1992, Sec. 4).

:func:`compute_flex` runs, part by part, the frozen-frequency sweeps of Figs. 7-13, the mode
shapes of Figs. 14-15, the deflected linkage of Figs. 16-19, the periodic responses of
Figs. 20-22 with their modal truncation study, and two sensitivities (the bearing spring at B
only, the responses without geometric stiffness); then it judges the paper's claims
(:func:`studies.flex_claims.compare_claims`). Drawing is :mod:`report.flex`.
"""

import dataclasses
import time

import numpy as np

from .flex_claims import compare_claims
from .flex_events import mac
from .flex_frequencies import BEARINGS, paper_frequency_cases, PAPER_RPM, SHAPE_ANGLES_DEG
from .flex_frequencies import sweep_case
from .flex_measures import bending_deflection
from .flex_truncation import truncation_study
from ..core.fe.linkage import FlexibleLinkage
from ..core.fe.modes import solve_frozen_modes
from ..core.fe.simulate import periodic_response
from ..core.mechanism_file import load_mechanism
from ..core.numerics import RPM
from ..core.options import ModelOptions

# Crank-angle step of the frequency sweeps [deg] (full / quick).
SWEEP_STEP_DEG = (1.0, 10.0)
# Time steps per revolution: full-order reference and rigid-bearing modal runs; modal runs with
# flexible bearings need finer steps (their basis-transfer error is ~4 % at 720, 0.3 % at 2880).
REFERENCE_STEPS = (720, 120)
MODAL_STEPS_FLEXIBLE = (2880, 240)
OUTPUT_POINTS = (120, 30)
# Speed of the mode-shape and deflected-linkage figures [rad/s] (Sec. 4.2-4.3).
SHAPE_SPEED_RAD_S = 30.0


def compute_flex(mechanism=None, quick=False):
    """
    Compute every number of the report section (no plotting).

    Parameters
    ----------
    mechanism : Mechanism or None
        Default: cho1992 (with 2 elements per link when ``quick``).
    quick : bool
        Reduced sizes for tests (coarser sweeps, steps and mode counts).

    Returns
    -------
    dict
        'mechanism', 'quick', 'seconds' {part: s}, 'sweeps' {key: Sweep}, 'shapes'
        {deg: ...}, 'linkage' (30 rad/s response and drawing data), 'responses'
        {(bearings, rpm): ...}, 'truncation' {(bearings, rpm): ...}, 'b_only_responses'
        {rpm: ...}, 'no_kg_responses' {(bearings, rpm): ...}, 'claims' (list of dict).

    """
    q = 1 if quick else 0
    if mechanism is None:
        mechanism = load_mechanism('cho1992')
        if quick:
            mechanism = dataclasses.replace(mechanism, elements_per_link=2)
    seconds = {}
    data = {'mechanism': mechanism, 'quick': quick, 'seconds': seconds}
    parts = (('frequency sweeps', _sweeps),
             ('mode shapes and deflected linkage', _shapes_and_linkage),
             ('responses and truncation study', _responses_and_truncation),
             ('spring at B only', _spring_at_b_only),
             ('responses without K_G', _responses_without_kg))
    for name, part in parts:
        started = time.perf_counter()
        data.update(part(mechanism, q))
        seconds[name] = time.perf_counter() - started
    data['claims'] = compare_claims(data)
    return data


def mode_counts(size, quick, dense=True):
    """
    Values of N for the truncation study.

    Dense: every N up to 8, then every other. Sparse (the costly fine-step runs): every N up
    to 6, then every fourth, and the last three.

    Parameters
    ----------
    size : int
        Degrees of freedom of the model (the largest N).
    quick : bool
        A handful of values only (tests).
    dense : bool
        Dense or sparse values.

    Returns
    -------
    ndarray of int

    """
    if quick:
        return np.array(sorted({1, 2, 4, size}))
    if dense:
        return np.array(sorted(set(range(1, 9)) | set(range(10, size, 2)) | {size - 1, size}))
    return np.array(sorted(set(range(1, 7)) | set(range(8, size - 2, 4))
                           | {size - 2, size - 1, size}))


def _rigid_crank_options(bearings, geometric=True):
    return ModelOptions.full_model(rigid_crank=True, bearings=bearings,
                                   geometric_stiffness=geometric)


def _sweeps(mechanism, q):
    """Frozen frequencies of every case of Figs. 7-13 over the crank angle."""
    crank_deg = np.arange(0.0, 360.0, SWEEP_STEP_DEG[q])
    return {'sweeps': {key: sweep_case(mechanism, case, crank_deg, count=3)
                       for key, case in paper_frequency_cases().items()}}


def _shapes_and_linkage(mechanism, q):
    """Mode shapes (Figs. 14-15) and the deflected linkage (Figs. 16-19)."""
    return {'shapes': {deg: _mode_shapes(mechanism, deg) for deg in SHAPE_ANGLES_DEG},
            'linkage': _deflected_linkage(mechanism, q)}


def _responses_and_truncation(mechanism, q):
    """Full-order responses (Figs. 20-22) and the modal truncation study, per bearings, rpm."""
    responses, truncation = {}, {}
    for bearings in BEARINGS:
        model = FlexibleLinkage(mechanism, _rigid_crank_options(bearings))
        for rpm in PAPER_RPM:
            speed = rpm * RPM
            reference = periodic_response(model, speed, 'full', steps=REFERENCE_STEPS[q],
                                          points=OUTPUT_POINTS[q])
            responses[bearings, rpm] = reference
            steps = MODAL_STEPS_FLEXIBLE[q] if bearings == 'flexible' else REFERENCE_STEPS[q]
            if steps != REFERENCE_STEPS[q]:
                reference_modal = periodic_response(model, speed, 'full', steps=steps,
                                                    points=OUTPUT_POINTS[q])
            else:
                reference_modal = reference
            counts = mode_counts(model.size, bool(q), dense=steps == REFERENCE_STEPS[q])
            study = truncation_study(model, speed, counts, steps=steps, points=OUTPUT_POINTS[q],
                                     reference=reference_modal)
            study['steps'] = steps
            truncation[bearings, rpm] = study
    return {'responses': responses, 'truncation': truncation}


def _spring_at_b_only(mechanism, q):
    """Sensitivity: the bearing spring at B only (Sec. 4.1 names the coupler-lever bearing)."""
    only_b = dataclasses.replace(mechanism, bearing_joints=('B',))
    model = FlexibleLinkage(only_b, _rigid_crank_options('flexible'))
    return {'b_only_responses': {rpm: periodic_response(model, rpm * RPM, 'full',
                                                        steps=REFERENCE_STEPS[q],
                                                        points=OUTPUT_POINTS[q])
                                 for rpm in PAPER_RPM}}


def _responses_without_kg(mechanism, q):
    """Compute the full-order responses again without geometric stiffness (Conclusion 1)."""
    responses = {}
    for bearings in BEARINGS:
        model = FlexibleLinkage(mechanism, _rigid_crank_options(bearings, False))
        for rpm in PAPER_RPM:
            responses[bearings, rpm] = periodic_response(
                model, rpm * RPM, 'full', steps=REFERENCE_STEPS[q], points=OUTPUT_POINTS[q])
    return {'no_kg_responses': responses}


def _mode_shapes(mechanism, deg):
    """Lowest 3 modes at one crank angle, all flexible and rigid crank (Figs. 14-15)."""
    theta = np.radians([deg])
    out = {}
    for key, rigid_crank in (('flex', False), ('rigid_crank', True)):
        model = FlexibleLinkage(mechanism, ModelOptions.full_model(rigid_crank=rigid_crank,
                                                                   geometric_stiffness=True))
        frozen = solve_frozen_modes(model.assemble(theta), 3, SHAPE_SPEED_RAD_S)
        positions, operator = model.shape_operator(theta)
        deflection = np.einsum('lpcn,nm->mlpc', operator[0], frozen.shapes[0])
        out[key] = {'positions': positions[0], 'deflection': deflection,
                    'frequencies_hz': frozen.frequencies_hz[0],
                    'dominant': frozen.dominant_link[0], 'strain_share': frozen.strain_share[0]}
    # Resemblance of the two models' modes on the coupler and lever (ground-frame deflections).
    flex = out['flex']['deflection'][:, 1:].reshape(3, -1).T
    rigid = out['rigid_crank']['deflection'][:, 1:].reshape(3, -1).T
    out['mac'] = mac(flex, rigid)
    # Draw each rigid-crank mode with the sign of the all-flexible mode it resembles.
    signs = np.where(np.einsum('pm,pm->m', flex, rigid) < 0.0, -1.0, 1.0)
    out['rigid_crank']['deflection'] = (out['rigid_crank']['deflection']
                                        * signs[:, None, None, None])
    return out


def _deflected_linkage(mechanism, q):
    """Periodic response at 30 rad/s, all links flexible, pins (Figs. 16-19), for drawing."""
    model = FlexibleLinkage(mechanism, ModelOptions.full_model(geometric_stiffness=True))
    response = periodic_response(model, SHAPE_SPEED_RAD_S, 'full', steps=REFERENCE_STEPS[q],
                                 points=OUTPUT_POINTS[q])
    positions, operator = model.shape_operator(response.crank_angle)
    deflection = np.einsum('klpcn,kn->klpc', operator, response.displacement)
    bending = {link: bending_deflection(model, response.displacement, response.crank_angle,
                                        link)
               for link in model.links}
    return {'crank_deg': np.degrees(response.crank_angle), 'positions': positions,
            'deflection': deflection, 'bending': bending, 'response': response}


__all__ = ['SWEEP_STEP_DEG', 'REFERENCE_STEPS', 'MODAL_STEPS_FLEXIBLE', 'OUTPUT_POINTS',
           'SHAPE_SPEED_RAD_S', 'compute_flex', 'mode_counts']
