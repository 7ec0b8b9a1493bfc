"""
Markdown with every number of the flexible four-bar report section (Cho 1992, Sec. 4).

:func:`report_text` joins one block per section: the model, the frozen frequencies, the mode
events, the peak-to-peak deflections, the modes needed per tolerance, the paper's claims and
the compute time, all read from a :func:`studies.flex_data.compute_flex` result.
"""

import numpy as np

from .flex_data import SWEEP_STEP_DEG
from .flex_measures import peak_to_peak
from .flex_truncation import modes_needed, TOLERANCES
from ..names import LINK_NAMES


def deflection_unit(values_m):
    """
    Scale and unit label for deflections: micrometres below 0.1 mm, mm otherwise.

    Parameters
    ----------
    values_m : array_like
        Deflections [m].

    Returns
    -------
    tuple of (float, str)

    """
    peak = np.abs(values_m).max() if np.size(values_m) else 0.0
    return (1e6, '\u00b5m') if peak < 1e-4 else (1e3, 'mm')


def _length(value_m):
    """Format a deflection for people: micrometres below 0.1 mm, millimetres otherwise."""
    scale, unit = deflection_unit(value_m)
    return f'{scale * value_m:.3g} {unit}' if unit != 'mm' else f'{scale * value_m:.3f} mm'


def _model_lines(data):
    mech = data['mechanism']
    return ['Geometric stiffness (A.4) is included where the paper includes it '
            '(axial forces from core/dynamics.py).',
            '', f'Model: {mech.elements_per_link} beam elements per link, gravity '
            f'{tuple(mech.gravity)} m/s^2, modal damping zeta = {mech.damping_ratio:g}, '
            f'flexible bearings k = {mech.bearing_stiffness / 1e3:g} kN/m at '
            f'{", ".join(mech.bearing_joints)}, '
            + ('clamped input shaft.' if mech.shaft_stiffness is None
               else f'input shaft k_t = {mech.shaft_stiffness:g} N m/rad.')]


def _frequency_lines(data):
    lines = ['', '### Frozen natural frequencies over the cycle [Hz]', '',
             '| case | mode 1 | mode 2 | mode 3 |', '|---|---|---|---|']
    for sweep in data['sweeps'].values():
        cells = []
        for m in range(3):
            f = sweep.frequencies_hz[:, m]
            links = sorted({LINK_NAMES[i] for i in sweep.dominant_link[:, m]})
            cells.append(f'{f.min():.2f}-{f.max():.2f} ({"/".join(links)})')
        lines.append(f'| {sweep.case.label} | ' + ' | '.join(cells) + ' |')
    return lines + ['', '(in brackets: the link holding most strain energy somewhere in the '
                    'cycle)']


def _event_lines(data):
    step = SWEEP_STEP_DEG[1 if data['quick'] else 0]
    lines = ['', '### Mode veering and order swaps (modes 1-3, '
             f'{step:g}-degree sweep)', '']
    events = [(s.case.label, e) for s in data['sweeps'].values() for e in s.events]
    if events:
        lines += ['| case | kind | modes | crank [deg] | gap at the samples [Hz] | '
                  'smallest gap [Hz] (at deg) | exchange MAC |', '|---|---|---|---|---|---|---|']
        lines += [f'| {label} | {e.kind} | {e.modes[0] + 1}-{e.modes[1] + 1} | '
                  f'{e.parameter % 360:.1f} | {e.gap:.3f} | {e.refined_gap:.4f} '
                  f'({e.refined_parameter:.2f}) | {e.exchange:.2f} |' for label, e in events]
        return lines + ['', f'A swap is an order change between {step:g}-degree samples; the '
                        'refined smallest gap says whether the modes truly cross (gap 0) or '
                        'veer sharply.']
    gaps = []
    for sweep in data['sweeps'].values():
        f = sweep.frequencies_hz
        gaps.append(f'{sweep.case.label}: modes 1-2 {np.min(f[:, 1] - f[:, 0]):.2f} Hz, '
                    f'2-3 {np.min(f[:, 2] - f[:, 1]):.2f} Hz')
    return lines + ['None: no veering and no order swap among modes 1-3 in any case. Smallest '
                    'gaps: ' + '; '.join(gaps) + '.']


def _deflection_lines(data):
    lines = ['', '### Peak-to-peak elastic deflections (rigid crank, full order)', '',
             '| bearings | rpm | lever tip X | lever tip Y | coupler mid X | coupler mid Y |',
             '|---|---|---|---|---|---|']
    for (bearings, rpm), response in data['responses'].items():
        p2p = peak_to_peak(response)
        lines.append(f'| {bearings} | {rpm:g} | ' + ' | '.join(_length(v) for v in p2p) + ' |')
    return lines


def _truncation_lines(data):
    lines = ['', '### Modes needed for a relative RMS error (mode superposition vs full '
             'order, rigid crank)', '',
             '| bearings | rpm | steps/rev | output | 1 % | 5 % | 1 % static corr. | '
             '5 % static corr. | error with all modes |', '|---|---|---|---|---|---|---|---|---|']
    for (bearings, rpm), study in data['truncation'].items():
        for o, name in enumerate(('lever tip', 'coupler mid')):
            cells = [modes_needed(study['modes'], study[key][:, o], tol)
                     for key in ('plain', 'static') for tol in TOLERANCES]
            cells = ['none' if c is None else str(c) for c in cells]
            lines.append(f'| {bearings} | {rpm:g} | {study["steps"]} | {name} | '
                         + ' | '.join(cells) + f' | {study["static"][-1, o]:.1e} |')
    return lines + ['', 'Total DOFs: rigid bearings '
                    f'{data["truncation"]["rigid", 269.0]["modes"][-1]}, flexible '
                    f'{data["truncation"]["flexible", 269.0]["modes"][-1]}. "Needed" means '
                    'every larger N tried also meets the target. Modal runs with flexible '
                    'bearings use finer steps: their step-to-step basis transfer loses a few '
                    'percent at 720 steps/rev whatever N is (a plateau in the chart).']


def _claim_lines(data):
    lines = ['', '### Paper claims (Sec. 4 and conclusions) against this model', '',
             '| where | paper says | we measure | verdict |', '|---|---|---|---|']
    for claim in data['claims']:
        lines.append(f'| {claim["where"]} | {claim["claim"]} | {claim["measured"]} | '
                     f'**{claim["verdict"]}** |')
    return lines


def _time_lines(data):
    return ['', 'Compute time: ' + ', '.join(f'{k} {v:.1f} s'
                                             for k, v in data['seconds'].items()) + '.']


SECTIONS = (_model_lines, _frequency_lines, _event_lines, _deflection_lines, _truncation_lines,
            _claim_lines, _time_lines)


def report_text(data):
    """
    Write the markdown with every number of the section.

    Parameters
    ----------
    data : dict
        A :func:`studies.flex_data.compute_flex` result.

    Returns
    -------
    str

    """
    return '\n'.join(line for section in SECTIONS for line in section(data))


__all__ = ['deflection_unit', 'report_text']
