"""
The estimator on the soft basis against the scene reference, beside the 26-coordinate step.

Every case streams a synthetic crank signal through the estimator (:func:`segment_replay.replay`,
the same numbers as streaming) with the soft basis (``soft_modes = -1``: the smallest p at a
usable gap) and without it (``soft_modes = 0``), and compares the outputs with the reference
of the scene (:func:`studies.plan.scene_options`: 6 elements per link, flexible crank,
geometric stiffness, full order, the model's output order): relative RMS over the last
revolution at constant speed (with and without +-30 % sample jitter) and over a
100 -> 600 rpm ramp.

The ramp has no periodic full-order reference, so it gets its own, independent of the
reduction (:func:`every_dof_options`): the scene's tables with every FE DOF kept (identity
basis, as the reference's own test builds them) on a 256-point
grid, stepped by the estimator at :data:`REFERENCE_RATE_HZ` (20x the signal's rate) over the
same crank motion. It is first checked against :func:`reference_response` at constant speed
(:func:`check_every_dof_reference`).

``python docs/studies/soft_basis_study.py`` prints the table. Measured (coupler
mid-point / lever tip, default model 24 + 2, grid 128, order 2):

=================  =============  =============
case               soft, p = 16   all 26
=================  =============  =============
269 rpm            0.53 / 0.22 %  1.29 / 0.59 %
391 rpm            0.78 / 0.71 %  1.01 / 0.86 %
269 rpm +-30 %     0.57 / 0.23 %  1.32 / 0.60 %
391 rpm +-30 %     0.88 / 0.86 %  1.12 / 0.99 %
100 rpm            0.00 / 0.00 %  0.07 / 0.14 %
600 rpm            1.09 / 1.74 %  1.17 / 1.78 %
100 -> 600 ramp    0.91 / 1.34 %  1.25 / 1.65 %
=================  =============  =============

The every-DOF reference differs from the periodic full order by 0.03 / 0.03 % at 391 and
600 rpm.
"""

import argparse
import dataclasses
import math

from flexlink_ros.core.estimation.segment_replay import replay
from flexlink_ros.core.numerics import relative_rms, RPM
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.core.reduction import reference as reduction_reference
from flexlink_ros.core.reduction.soft_basis import lowest_modes
from flexlink_ros.core.reduction.soft_tables import node_values
from flexlink_ros.studies.peer_model import resolve_mechanism
from flexlink_ros.studies.plan import full_order_dofs, scene_options
from flexlink_ros.studies.synthetic import last_revolution, synthetic_signal
import numpy as np

# (label, rpm, jitter) of the constant-speed cases, and the targets (relative RMS).
STEADY_CASES = (('269 rpm', 269.0, 0.0), ('391 rpm', 391.0, 0.0),
                ('269 rpm +-30 %', 269.0, 0.3), ('391 rpm +-30 %', 391.0, 0.3),
                ('100 rpm', 100.0, 0.0), ('600 rpm', 600.0, 0.0))
RAMP_LABEL = '100 -> 600 rpm ramp'
TARGETS = {'269 rpm': 0.008, '391 rpm': 0.008, '269 rpm +-30 %': 0.010,
           '391 rpm +-30 %': 0.010, '100 rpm': 0.02, '600 rpm': 0.02, RAMP_LABEL: 0.02}
# The ramp: a revolution at the first speed, a linear ramp, a short hold at the last [s].
RAMP_RPM = (100.0, 600.0)
RAMP_SECONDS = 2.0
RAMP_HOLD_S = 0.2
# The every-DOF reference's grid and its step rate as a multiple of the signal's.
REFERENCE_GRID = 256
REFERENCE_RATE_FACTOR = 20
REFERENCE_RATE_HZ = REFERENCE_RATE_FACTOR * 1000.0
OUTPUTS = ('coupler_mid', 'lever_tip')


def study_scene(options):
    """Give the reference of the default model: the plan's scene with twice the elements."""
    return scene_options(resolve_mechanism('cho1992'),
                         dataclasses.replace(options, elements_per_link=None))


def ramp_signal(rpm_start, rpm_end, ramp_s, rate_hz, hold_end_s=RAMP_HOLD_S):
    """
    Stamps, angles and speeds of a crank ramping linearly between two speeds.

    One revolution at ``rpm_start``, a linear ramp over ``ramp_s`` seconds, ``hold_end_s``
    at ``rpm_end``; sampled exactly at ``rate_hz`` (integer nanosecond steps), angles the
    exact integral of the speed.

    Returns
    -------
    stamps_ns : ndarray of int
    angles, speeds : ndarray
    ramp_start_s : float
        When the ramp starts [s].

    """
    start, end = rpm_start * RPM, rpm_end * RPM
    hold = 2.0 * math.pi / start
    step_ns = int(round(1e9 / rate_hz))
    stamps = np.arange(0, int((hold + ramp_s + hold_end_s) * 1e9), step_ns, dtype=np.int64)
    t = stamps * 1e-9
    ramp_t = np.clip(t - hold, 0.0, ramp_s)
    accel = (end - start) / ramp_s
    speeds = start + accel * ramp_t
    angles = start * np.minimum(t, hold) + start * ramp_t + 0.5 * accel * ramp_t ** 2 \
        + end * np.maximum(t - hold - ramp_s, 0.0)
    return stamps, angles, speeds, hold


def every_dof_options(mechanism, scene, grid_size=REFERENCE_GRID):
    """Options of the scene's tables with every FE DOF kept (no reduction, no soft basis)."""
    return dataclasses.replace(scene, modes=full_order_dofs(mechanism, scene), static=0,
                               grid_size=grid_size, soft_modes=0)


def _errors(estimate, reference, mask=slice(None)):
    return {key: relative_rms(estimate[key][mask], reference[key]) for key in OUTPUTS}


def steady_error(mechanism, model, reference_options, rpm, rate_hz=1000.0, jitter=0.0,
                 steps=reduction_reference.REFERENCE_STEPS):
    """
    Error of ``model`` over the last of two revolutions at ``rpm`` against the full order.

    The estimator replays a synthetic signal (``jitter`` as :func:`synthetic_signal`) and its
    last revolution is compared with :func:`reference_response` of ``reference_options``
    (``steps`` per revolution) at the same crank angles.

    Returns
    -------
    dict
        'coupler_mid', 'lever_tip': relative RMS.

    """
    stamps, angles, speeds = synthetic_signal(rpm, 4.0 * math.pi / (rpm * RPM), rate_hz, jitter)
    out = replay(model, stamps, angles, speeds)
    mask = last_revolution(stamps, rpm)
    ref = reduction_reference.reference_response(mechanism, reference_options, rpm * RPM,
                                                 angles[mask], steps)
    return _errors(out, ref, mask)


def check_every_dof_reference(mechanism, scene, reference_model, rpm,
                              factor=REFERENCE_RATE_FACTOR,
                              steps=reduction_reference.REFERENCE_STEPS):
    """Measure the every-DOF reference stepped at ``factor`` kHz against the periodic one."""
    return steady_error(mechanism, reference_model, scene, rpm, factor * 1000.0, steps=steps)


def ramp_error(model, reference_model, ramp_s=RAMP_SECONDS, rate_hz=1000.0,
               factor=REFERENCE_RATE_FACTOR):
    """
    Error of ``model`` at ``rate_hz`` over the ramp against the every-DOF reference.

    The reference steps the same crank motion at ``factor`` times the rate; the samples from
    the start of the ramp on are compared.

    Returns
    -------
    dict
        'coupler_mid', 'lever_tip': relative RMS.

    """
    fine = ramp_signal(*RAMP_RPM, ramp_s, factor * rate_hz)
    reference = replay(reference_model, *fine[:3])
    stamps, angles, speeds, ramp_start = ramp_signal(*RAMP_RPM, ramp_s, rate_hz)
    count = min(stamps.size, (fine[0].size + factor - 1) // factor)
    estimate = replay(model, stamps[:count], angles[:count], speeds[:count])
    mask = stamps[:count] * 1e-9 >= ramp_start
    return {key: relative_rms(estimate[key][mask], reference[key][::factor][:count][mask])
            for key in OUTPUTS}


def case_errors(mechanism, models, reference_options, cases, reference_model=None,
                ramp_s=RAMP_SECONDS, steps=reduction_reference.REFERENCE_STEPS):
    """
    Errors of each model in every case: {label: {case: {'coupler_mid', 'lever_tip'}}}.

    ``models`` maps labels to models. Constant-speed cases (:func:`steady_error`, every
    model on one reference per case) against ``reference_options``'s full order; the ramp
    (if ``reference_model`` is given) against the every-DOF reference.
    """
    errors = {label: {} for label in models}
    for case, rpm, jitter in cases:
        for label, model in models.items():
            errors[label][case] = steady_error(mechanism, model, reference_options, rpm,
                                               jitter=jitter, steps=steps)
    if reference_model is not None:
        for label, model in models.items():
            errors[label][RAMP_LABEL] = ramp_error(model, reference_model, ramp_s)
    return errors


def soft_pair(mechanism, options):
    """Give the model of ``options`` with the soft basis (-1) and without (0): (soft, full)."""
    soft = mechanism_model.model_for_mechanism(mechanism,
                                               dataclasses.replace(options, soft_modes=-1))
    return soft, mechanism_model.with_soft_basis(dataclasses.replace(soft, soft=None), 0)


def paper_scenes():
    """List the paper's rigid-crank scenes: (label, options), flexible and rigid bearings."""
    return [('rigid crank, flexible bearings (16 + 2)',
             dataclasses.replace(ModelOptions(), rigid_crank=True,
                                 elements_per_link=None, modes=16, static=2)),
            ('rigid crank, rigid bearings (4 + 2)',
             dataclasses.replace(ModelOptions(), rigid_crank=True,
                                 elements_per_link=None, bearings='rigid', modes=4, static=2))]


def run_study(mechanism=None, options=None, cases=STEADY_CASES, ramp_s=RAMP_SECONDS,
              paper_cases=STEADY_CASES[:4], scene=None,
              steps=reduction_reference.REFERENCE_STEPS):
    """
    Measure the default model with and without the soft basis, and the paper's scenes.

    Returns
    -------
    dict
        'rows': list of {'label', 'soft' (model.info['soft']), 'size' (coordinates stepped),
        'errors': {case: {'coupler_mid', 'lever_tip'}}}; 'reference_check' (the every-DOF
        reference against the periodic full order at 391 and 600 rpm); 'scene'.

    """
    mechanism = mechanism or resolve_mechanism('cho1992')
    options = options or ModelOptions()
    scene = scene or study_scene(options)
    reference_model = None
    check = {}
    if ramp_s:
        grid = min(REFERENCE_GRID, 2 * options.grid_size)
        reference_model = mechanism_model.model_for_mechanism(
            mechanism, every_dof_options(mechanism, scene, grid))
        check = {rpm: check_every_dof_reference(mechanism, scene, reference_model, rpm,
                                                steps=steps)
                 for rpm in (RAMP_RPM[1], 391.0)}
    soft, full = soft_pair(mechanism, options)
    models = {'default, soft basis': soft, f'default, all {full.size} coordinates': full}
    errors = case_errors(mechanism, models, scene, cases, reference_model, ramp_s, steps)
    rows = [_row(label, model, errors[label]) for label, model in models.items()]
    for label, paper in paper_scenes() if paper_cases else ():
        soft, full = soft_pair(mechanism, paper)
        models = {label + ', soft basis': soft, label + ', all coordinates': full}
        errors = case_errors(mechanism, models, paper, paper_cases, steps=steps)
        rows += [_row(name, model, errors[name]) for name, model in models.items()]
    return {'rows': rows, 'reference_check': check, 'scene': dataclasses.asdict(scene)}


def veering_options():
    """
    Give a model whose modes veer inside the soft subspace: flexible crank, rigid bearings.

    4 elements per link, 8 + 4 directions, grid 64: p = 7 at a gap of 6.8x, and at 391 rpm
    its two lowest modes swap order twice a revolution, there and back
    (:func:`mode_order`).
    """
    return ModelOptions.linear(bearings='rigid', rigid_crank=False, elements_per_link=4,
                               grid_size=64)


def mode_order(model, speed, count):
    """
    Follow each of the lowest ``count`` modes of node 0 around the revolution.

    At every grid node, the modes of K(theta) + w^2 K_w2(theta) against M(theta) (the
    frozen modes at crank speed ``speed``, no acceleration), and for each mode of node 0 the
    index of the node's mode it overlaps most in the mass norm (|x_k^T M_k v|): a mode
    that keeps its order keeps its index; a swap shows as the index changing.

    Returns
    -------
    ndarray of int, shape (N, count)
        The index of node 0's mode i at node k.

    """
    mass = node_values(model, 'M')['1']
    pieces = node_values(model, 'K')
    stiffness = pieces['1'] + speed * speed * pieces.get('w2', np.zeros_like(pieces['1']))
    _, modes = lowest_modes(mass, stiffness, model.size)
    start = modes[0][:, :count]
    overlaps = np.abs(np.einsum('nri,nrs,sj->nij', modes, mass, start))
    return np.argmax(overlaps, axis=1)


def _row(label, model, errors):
    return {'label': label, 'soft': dict(model.info.get('soft', {})),
            'size': int(model.step_size), 'record_size': int(model.size), 'errors': errors}


def study_table(result):
    """Markdown table of :func:`run_study`: coupler mid-point / lever tip per case."""
    cases = list(dict.fromkeys(c for row in result['rows'] for c in row['errors']))
    lines = ['| model | stepped | ' + ' | '.join(cases) + ' |',
             '|---|---|' + '---|' * len(cases)]
    for row in result['rows']:
        cells = []
        for case in cases:
            e = row['errors'].get(case)
            cells.append('-' if e is None else
                         f'{100 * e["coupler_mid"]:.2f} / {100 * e["lever_tip"]:.2f} %')
        lines.append(f'| {row["label"]} | {row["size"]} | ' + ' | '.join(cells) + ' |')
    lines.append('| target (coupler and lever) | | ' + ' | '.join(
        f'<= {100 * TARGETS[c]:g} %' if c in TARGETS else '' for c in cases) + ' |')
    for rpm, check in result['reference_check'].items():
        lines.append(f'every-DOF ramp reference vs periodic full order at {rpm:g} rpm: '
                     f'{100 * check["coupler_mid"]:.3f} / {100 * check["lever_tip"]:.3f} %')
    return '\n'.join(lines)


def main(argv=None):
    """Print the study's table (``--no-ramp``, ``--no-paper`` leave parts out)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--no-ramp', action='store_true', help='leave out the ramp')
    parser.add_argument('--no-paper', action='store_true',
                        help="leave out the paper's rigid-crank scenes")
    args = parser.parse_args(argv)
    result = run_study(ramp_s=0.0 if args.no_ramp else RAMP_SECONDS,
                       paper_cases=() if args.no_paper else STEADY_CASES[:4])
    print(study_table(result))


if __name__ == '__main__':
    main()
