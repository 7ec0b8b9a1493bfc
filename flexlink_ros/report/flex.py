"""
Charts and numbers of the flexible four-bar FE model (Cho, Park & Lee 1992, Sec. 4).

:func:`plot_flex` (the ``flexlink report`` section) computes everything once
(:func:`compute_flex`) and writes:

- ``flex_frequencies_fig7.png``: lowest frozen frequencies vs crank angle, all links flexible,
  no geometric stiffness (Fig. 7), veerings and swaps marked.
- ``flex_frequencies_fig8_10.png``: modes 1-3, all flexible vs rigid crank, with and without
  K_G at 30 and 45 rad/s (Figs. 8-10); without core/dynamics.py only the K_G-free curves.
- ``flex_frequencies_fig11_13.png``: rigid crank, rigid vs flexible bearings, 30 and 45 rad/s
  (Figs. 11-13).
- ``flex_mode_shapes_27deg.png``, ``flex_mode_shapes_123deg.png``: lowest three mode shapes,
  all flexible and rigid crank (Figs. 14-15), at the paper's scale (mass-normalised x 4e-3).
- ``flex_deflected_linkage.png``: the deflected linkage every 3 degrees at 30 rad/s in four
  quarter-turn panels (Figs. 16-19), deflections exaggerated by a stated factor.
- ``flex_lever_tip.png``, ``flex_coupler_mid.png``: ground-frame X and Y elastic deflections
  at 269 and 391 rpm, rigid and flexible bearings, rigid crank (Figs. 20-21).
- ``flex_coupler_path.png``: coupler mid-point paths, rigid and flexible (Fig. 22), and the
  elastic deflection loops.
- ``flex_truncation.png``: relative RMS error of mode superposition vs number of modes N,
  with and without static correction, both speeds and bearing models.

The markdown text carries the numbers: frequency ranges, mode events, peak-to-peak
deflections, modes needed for 1 % and 5 %, and the comparison with each claim of Sec. 4.
"""

import dataclasses
import pathlib
import time

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from ..core.numerics import RPM
from ..studies import flex_study as fs
from ..core.options import ModelOptions
from ..core.fe.linkage import FlexibleLinkage
from ..core.kinematics import solve_kinematics
from ..core.mechanism import LINK_NAMES, load_mechanism
from ..core.fe.modes import solve_frozen_modes
from ..core.fe.simulate import periodic_response

# Crank-angle step of the frequency sweeps [deg] (full / quick).
SWEEP_STEP_DEG = (1.0, 10.0)
# Time steps per revolution: full-order reference and rigid-bearing modal runs; modal runs with
# flexible bearings need finer steps (their basis-transfer error is ~4 % at 720, 0.3 % at 2880).
REFERENCE_STEPS = (720, 120)
MODAL_STEPS_FLEXIBLE = (2880, 240)
OUTPUT_POINTS = (120, 30)
# The paper's mode-shape angles [deg] and scale (mass-normalised eigenvector x 4/1000).
SHAPE_ANGLES_DEG = (27.0, 123.0)
SHAPE_SCALE = 4e-3
# Speed of the mode-shape and deflected-linkage figures [rad/s] (Sec. 4.2-4.3).
SHAPE_SPEED_RAD_S = 30.0
# Quarter-turn panels of Figs. 16-19 [deg] (start, stop) every 3 degrees.
QUARTERS_DEG = ((45.0, 132.0), (135.0, 222.0), (225.0, 312.0), (315.0, 402.0))
BEARINGS = ('rigid', 'flexible')
LINK_COLOURS = ('tab:green', 'tab:blue', 'tab:red')
MODE_COLOURS = ('tab:blue', 'tab:orange', 'tab:green', 'tab:purple')
DPI = 120


def _mode_counts(size, quick, dense=True):
    """
    Values of N for the truncation study.

    Dense: every N up to 8, then every other. Sparse (the costly fine-step runs): every N up
    to 6, then every fourth, and the last three.
    """
    if quick:
        return np.array(sorted({1, 2, 4, size}))
    if dense:
        return np.array(sorted(set(range(1, 9)) | set(range(10, size, 2)) | {size - 1, size}))
    return np.array(sorted(set(range(1, 7)) | set(range(8, size - 2, 4))
                           | {size - 2, size - 1, size}))


def _rigid_crank_options(bearings, geometric):
    return ModelOptions.full_model(rigid_crank=True, bearings=bearings, geometric_stiffness=geometric)


def compute_flex(mechanism=None, quick=False):
    """
    Every number of the report section (no plotting).

    Parameters
    ----------
    mechanism : Mechanism or None
        Default: cho1992 (with 2 elements per link when ``quick``).
    quick : bool
        Reduced sizes for tests (coarser sweeps, steps and mode counts).

    Returns
    -------
    dict
        'geometric' (bool), 'geometric_reason', 'sweeps' {key: Sweep}, 'shapes' {deg: ...},
        'linkage' (30 rad/s response and drawing data), 'responses' {(bearings, rpm): ...},
        'truncation' {(bearings, rpm): ...}, 'claims' (list of dict), 'seconds' {part: s}.

    """
    q = 1 if quick else 0
    if mechanism is None:
        mechanism = load_mechanism('cho1992')
        if quick:
            mechanism = dataclasses.replace(mechanism, elements_per_link=2)
    geometric, reason = True, ''   # TODO(studies helper): drop the flag, K_G is always built
    seconds = {}
    data = {'geometric': geometric, 'geometric_reason': reason, 'mechanism': mechanism,
            'quick': quick, 'seconds': seconds}

    started = time.perf_counter()
    crank_deg = np.arange(0.0, 360.0, SWEEP_STEP_DEG[q])
    data['sweeps'] = {key: fs.sweep_case(mechanism, case, crank_deg, count=3)
                      for key, case in fs.paper_frequency_cases(geometric).items()}
    seconds['frequency sweeps'] = time.perf_counter() - started

    started = time.perf_counter()
    data['shapes'] = {deg: _mode_shapes(mechanism, deg, geometric) for deg in SHAPE_ANGLES_DEG}
    data['linkage'] = _deflected_linkage(mechanism, geometric, q)
    seconds['mode shapes and deflected linkage'] = time.perf_counter() - started

    started = time.perf_counter()
    data['responses'], data['truncation'] = {}, {}
    for bearings in BEARINGS:
        model = FlexibleLinkage(mechanism, _rigid_crank_options(bearings, geometric))
        for rpm in fs.PAPER_RPM:
            speed = rpm * RPM
            reference = periodic_response(model, speed, 'full', steps=REFERENCE_STEPS[q],
                                          points=OUTPUT_POINTS[q])
            data['responses'][bearings, rpm] = reference
            steps = MODAL_STEPS_FLEXIBLE[q] if bearings == 'flexible' else REFERENCE_STEPS[q]
            if steps != REFERENCE_STEPS[q]:
                reference_modal = periodic_response(model, speed, 'full', steps=steps,
                                                    points=OUTPUT_POINTS[q])
            else:
                reference_modal = reference
            counts = _mode_counts(model.size, quick, dense=steps == REFERENCE_STEPS[q])
            study = fs.truncation_study(model, speed, counts,
                                        steps=steps, points=OUTPUT_POINTS[q],
                                        reference=reference_modal)
            study['steps'] = steps
            data['truncation'][bearings, rpm] = study
    seconds['responses and truncation study'] = time.perf_counter() - started

    # Sensitivity: the bearing spring at B only (Sec. 4.1 names the coupler-lever bearing).
    started = time.perf_counter()
    only_b = dataclasses.replace(mechanism, bearing_joints=('B',))
    model = FlexibleLinkage(only_b, _rigid_crank_options('flexible', geometric))
    data['b_only_responses'] = {rpm: periodic_response(model, rpm * RPM, 'full',
                                                       steps=REFERENCE_STEPS[q],
                                                       points=OUTPUT_POINTS[q])
                                for rpm in fs.PAPER_RPM}
    seconds['spring at B only'] = time.perf_counter() - started

    if geometric:
        started = time.perf_counter()
        data['no_kg_responses'] = {}
        for bearings in BEARINGS:
            model = FlexibleLinkage(mechanism, _rigid_crank_options(bearings, False))
            for rpm in fs.PAPER_RPM:
                data['no_kg_responses'][bearings, rpm] = periodic_response(
                    model, rpm * RPM, 'full', steps=REFERENCE_STEPS[q],
                    points=OUTPUT_POINTS[q])
        seconds['responses without K_G'] = time.perf_counter() - started
    data['claims'] = compare_claims(data)
    return data


def _mode_shapes(mechanism, deg, geometric):
    """Lowest 3 modes at one crank angle, all flexible and rigid crank (Figs. 14-15)."""
    theta = np.radians([deg])
    out = {}
    for key, rigid_crank in (('flex', False), ('rigid_crank', True)):
        model = FlexibleLinkage(mechanism, ModelOptions.full_model(rigid_crank=rigid_crank,
                                                        geometric_stiffness=geometric))
        frozen = solve_frozen_modes(model.assemble(theta), 3,
                                    SHAPE_SPEED_RAD_S if geometric else 0.0)
        positions, operator = model.shape_operator(theta)
        deflection = np.einsum('lpcn,nm->mlpc', operator[0], frozen.shapes[0])
        out[key] = {'positions': positions[0], 'deflection': deflection,
                    'frequencies_hz': frozen.frequencies_hz[0],
                    'dominant': frozen.dominant_link[0], 'strain_share': frozen.strain_share[0]}
    # Resemblance of the two models' modes on the coupler and lever (ground-frame deflections).
    flex = out['flex']['deflection'][:, 1:].reshape(3, -1).T
    rigid = out['rigid_crank']['deflection'][:, 1:].reshape(3, -1).T
    out['mac'] = fs.mac(flex, rigid)
    # Draw each rigid-crank mode with the sign of the all-flexible mode it resembles.
    signs = np.where(np.einsum('pm,pm->m', flex, rigid) < 0.0, -1.0, 1.0)
    out['rigid_crank']['deflection'] = out['rigid_crank']['deflection'] * signs[:, None, None,
                                                                               None]
    return out


def _deflected_linkage(mechanism, geometric, q):
    """Periodic response at 30 rad/s, all links flexible, pins (Figs. 16-19), for drawing."""
    model = FlexibleLinkage(mechanism, ModelOptions.full_model(geometric_stiffness=geometric))
    response = periodic_response(model, SHAPE_SPEED_RAD_S, 'full', steps=REFERENCE_STEPS[q],
                                 points=OUTPUT_POINTS[q])
    positions, operator = model.shape_operator(response.crank_angle)
    deflection = np.einsum('klpcn,kn->klpc', operator, response.displacement)
    bending = {link: fs.bending_deflection(model, response.displacement,
                                           response.crank_angle, link)
               for link in model.links}
    return {'crank_deg': np.degrees(response.crank_angle), 'positions': positions,
            'deflection': deflection, 'bending': bending, 'response': response}


# -- claims ------------------------------------------------------------------------------------


def _variation(sweep, mode):
    """(min, max, max - min) of a mode's frequency over the cycle [Hz]."""
    f = sweep.frequencies_hz[:, mode]
    return f.min(), f.max(), f.max() - f.min()


def compare_claims(data):
    """
    The qualitative claims of Cho 1992 Sec. 4 and conclusions, each against our numbers.

    Returns
    -------
    list of dict
        'where', 'claim', 'measured', 'verdict' ('agree', 'disagree', 'partly', or
        'not computed').

    """
    sweeps, claims = data['sweeps'], []

    def add(where, claim, measured, verdict):
        claims.append({'where': where, 'claim': claim, 'measured': measured,
                       'verdict': verdict})

    flex = sweeps['flex']
    spans = [_variation(flex, m)[2] for m in range(3)]
    add('Fig. 7', 'without K_G, modes 1 and 2 vary little over the cycle, mode 3 a lot',
        'variation (max-min) ' + ', '.join(f'mode {m + 1}: {s:.2f} Hz' for m, s in
                                           enumerate(spans)),
        'agree' if spans[2] > 5 * max(spans[:2]) else 'disagree')

    geometric = data['geometric']
    if geometric:
        for speed in fs.PAPER_SPEEDS_RAD_S[:1]:
            kg, kg_rc = sweeps[f'flex_kg_{speed:g}'], sweeps[f'rigid_crank_kg_{speed:g}']
            rc = sweeps['rigid_crank']
            rows, ok_kg, ok_flex = [], True, True
            for m in range(2):
                a, b, c, d = (_variation(s, m)[2] for s in (kg, kg_rc, flex, rc))
                rows.append(f'mode {m + 1}: all flexible {c:.2f} -> {a:.2f} Hz, rigid crank '
                            f'{d:.2f} -> {b:.2f} Hz')
                ok_kg &= a > c and b > d
                ok_flex &= a > b
            verdict = 'agree' if ok_kg and ok_flex else ('partly' if ok_kg or ok_flex
                                                         else 'disagree')
            add('Figs. 8-9', 'K_G widens the variation of modes 1-2, more with all links '
                'flexible than with a rigid crank', f'variation without -> with K_G at '
                f'{speed:g} rad/s: ' + '; '.join(rows), verdict)
            shift_kg = np.abs(kg.frequencies_hz[:, 2] - flex.frequencies_hz[:, 2]).max()
            shift_crank = np.abs(kg_rc.frequencies_hz[:, 2] - kg.frequencies_hz[:, 2]).max()
            add('Fig. 10', 'mode 3: K_G matters little, crank flexibility a lot',
                f'max shift by K_G {shift_kg:.2f} Hz, by a rigid crank {shift_crank:.1f} Hz',
                'agree' if shift_crank > 5 * shift_kg else 'disagree')
    else:
        rc = sweeps['rigid_crank']
        shift_crank = np.abs(rc.frequencies_hz[:, 2] - flex.frequencies_hz[:, 2]).max()
        add('Figs. 8-9', 'K_G widens the variation of modes 1-2', 'K_G not computed: '
            + data['geometric_reason'], 'not computed')
        add('Fig. 10', 'mode 3: K_G matters little, crank flexibility a lot',
            f'crank flexibility shifts mode 3 by up to {shift_crank:.1f} Hz (K_G part not '
            'computed)', 'partly')

    suffix = f'_kg_{fs.PAPER_SPEEDS_RAD_S[0]:g}' if geometric else ''
    rigid_b, flex_b = sweeps['rigid_crank' + suffix], sweeps['rigid_crank_bearings' + suffix]
    drops = flex_b.frequencies_hz - rigid_b.frequencies_hz
    add('Figs. 11-13', 'flexible bearings lower the frequencies of all three modes',
        'flexible minus rigid bearings, over the cycle: ' + ', '.join(
            f'mode {m + 1} {drops[:, m].min():.1f} to {drops[:, m].max():.1f} Hz'
            for m in range(3)) + ' (springs at all four joints)',
        'agree' if np.all(drops < 0) else 'disagree')
    if geometric:
        slow = sweeps[f'rigid_crank_bearings_kg_{fs.PAPER_SPEEDS_RAD_S[0]:g}']
        fast = sweeps[f'rigid_crank_bearings_kg_{fs.PAPER_SPEEDS_RAD_S[1]:g}']
        growth = [_variation(fast, m)[2] / max(_variation(slow, m)[2], 1e-12) for m in range(3)]
        add('Figs. 11-13', 'higher speed (45 vs 30 rad/s) widens the variation, most in '
            'modes 1-2', 'variation ratio 45/30 rad/s: ' + ', '.join(
                f'mode {m + 1} {g:.2f}' for m, g in enumerate(growth)),
            'agree' if min(growth[:2]) > 1 and max(growth[:2]) > growth[2] else
            ('partly' if max(growth) > 1 else 'disagree'))
    else:
        add('Figs. 11-13', 'higher speed widens the variation of the frequencies',
            'needs K_G (without it the frozen frequencies do not depend on speed)',
            'not computed')

    shapes = data['shapes']
    macs = {deg: np.diag(shapes[deg]['mac']) for deg in SHAPE_ANGLES_DEG}
    swapped = [d for d in SHAPE_ANGLES_DEG
               if min(shapes[d]['mac'][0, 1], shapes[d]['mac'][1, 0]) > 0.5]
    add('Figs. 14-15', 'crank flexibility changes the mode shapes, mode 3 most',
        'MAC of all-flexible vs rigid-crank modes on coupler and lever: ' + '; '.join(
            f'{deg:g} deg: ' + ', '.join(f'{v:.2f}' for v in macs[deg])
            for deg in SHAPE_ANGLES_DEG) + ''.join(
            f'; at {d:g} deg modes 1 and 2 trade places between the models (cross MAC '
            f'{shapes[d]["mac"][0, 1]:.2f}, {shapes[d]["mac"][1, 0]:.2f})' for d in swapped),
        'agree' if all(macs[d][2] < min(macs[d][:2]) for d in SHAPE_ANGLES_DEG) else 'partly')
    names = {deg: [LINK_NAMES[i] for i in shapes[deg]['flex']['dominant']]
             for deg in SHAPE_ANGLES_DEG}
    paper = {27.0: ['lever', 'coupler'], 123.0: ['coupler', 'lever']}
    matches = [names[d][:2] == paper[d] for d in SHAPE_ANGLES_DEG]
    def dominated(d, key):
        data = shapes[d][key]
        return ', '.join(f'{LINK_NAMES[i]} ({data["strain_share"][m, i]:.0%})'
                         for m, i in enumerate(data['dominant']))

    add('Sec. 4.2', 'all flexible: at 27 deg mode 1 is the lever, mode 2 the coupler; at '
        '123 deg mode 1 the coupler, mode 2 the lever', '; '.join(
            f'{d:g} deg: modes 1-3 dominated by ' + dominated(d, 'flex')
            for d in SHAPE_ANGLES_DEG) + ' (strain-energy share)',
        'agree' if all(matches) else ('partly' if any(matches) else 'disagree'))
    rc_names = {deg: [LINK_NAMES[i] for i in shapes[deg]['rigid_crank']['dominant']]
                for deg in SHAPE_ANGLES_DEG}
    ok = all(rc_names[d][:2] == ['coupler', 'lever'] for d in SHAPE_ANGLES_DEG)
    add('Sec. 4.2', 'rigid crank: mode 1 is the coupler, mode 2 the lever', '; '.join(
        f'{d:g} deg: ' + dominated(d, 'rigid_crank') for d in SHAPE_ANGLES_DEG),
        'agree' if ok else 'disagree')
    dominant = flex.dominant_link
    share = [(dominant[:, m] == link).mean() for m, link in enumerate((1, 2, 0))]
    add('Conclusion 2', 'mode 1 is the coupler, mode 2 the lever, mode 3 the crank',
        'share of the cycle where it holds (all flexible, pins, no K_G): ' + ', '.join(
            f'mode {m + 1} {s:.0%}' for m, s in enumerate(share)),
        'agree' if min(share) > 0.9 else ('partly' if max(share) > 0.5 else 'disagree'))
    if geometric:
        kg = sweeps[f'flex_kg_{fs.PAPER_SPEEDS_RAD_S[0]:g}'].dominant_link
        share_kg = [(kg[:, m] == link).mean() for m, link in enumerate((1, 2, 0))]
        claims[-1]['measured'] += '; with K_G at 30 rad/s: ' + ', '.join(
            f'mode {m + 1} {s:.0%}' for m, s in enumerate(share_kg))
        if min(share_kg) <= 0.9 and claims[-1]['verdict'] == 'agree':
            claims[-1]['verdict'] = 'partly'

    link = data['linkage']
    s, bending = link['bending'][1]
    template = fs.uniform_load_shape(s)
    peak = np.abs(bending).max(axis=1).argmax()
    corr = {name: abs(fs.shape_correlation(link['bending'][i][1][peak], template)[0])
            for i, name in ((1, 'coupler'), (2, 'lever'))}
    crank = np.abs(link['deflection'][:, 0]).max()
    coupler = np.abs(link['deflection'][:, 1]).max()
    add('Figs. 16-19', 'coupler and lever bend like simply supported beams under distributed '
        'load; the crank deflects too little to see',
        f'correlation with the uniform-load shape at the largest coupler bending '
        f'({link["crank_deg"][peak] % 360:.0f} deg): coupler {corr["coupler"]:.3f}, lever '
        f'{corr["lever"]:.3f}; largest crank deflection {1e6 * crank:.1f} \u00b5m vs coupler '
        f'{1e3 * coupler:.2f} mm', 'agree' if min(corr.values()) > 0.95 and
        crank < 0.05 * coupler else 'partly')

    responses = data['responses']
    p2p = {key: _p2p(r) for key, r in responses.items()}
    ratio_tip = [np.hypot(*p2p['flexible', rpm][:2]) / np.hypot(*p2p['rigid', rpm][:2])
                 for rpm in fs.PAPER_RPM]
    add('Fig. 20', 'lever tip: tiny with rigid bearings, relatively very large with flexible',
        ', '.join(f'{rpm:g} rpm: {1e6 * np.hypot(*p2p["rigid", rpm][:2]):.1f} \u00b5m vs '
                  f'{1e3 * np.hypot(*p2p["flexible", rpm][:2]):.2f} mm (x{r:.0f})'
                  for rpm, r in zip(fs.PAPER_RPM, ratio_tip))
        + ' (peak-to-peaks combined as hypot(X, Y))',
        'agree' if min(ratio_tip) > 10 else 'disagree')
    ratio_mid = [np.hypot(*p2p['flexible', rpm][2:]) / np.hypot(*p2p['rigid', rpm][2:])
                 for rpm in fs.PAPER_RPM]
    ratio_b = [np.hypot(*_p2p(data['b_only_responses'][rpm])[2:])
               / np.hypot(*p2p['rigid', rpm][2:]) for rpm in fs.PAPER_RPM]
    add('Fig. 21', 'coupler mid-point: bearing flexibility changes it little',
        'flexible / rigid bearings, peak-to-peaks combined as hypot(X, Y): ' + ', '.join(
            f'{rpm:g} rpm x{r:.2f}' for rpm, r in zip(fs.PAPER_RPM, ratio_mid))
        + ' (springs at all four joints); with the spring at B only: ' + ', '.join(
            f'{rpm:g} rpm x{r:.2f}' for rpm, r in zip(fs.PAPER_RPM, ratio_b)),
        'agree' if max(abs(r - 1) for r in ratio_mid) < 0.25 else
        ('partly' if min(abs(r - 1) for r in ratio_mid) < 0.25 else 'disagree'))
    harmonics = {}
    for bearings in BEARINGS:
        for rpm in fs.PAPER_RPM:
            shares = fs.harmonic_shares(responses[bearings, rpm].outputs[:, 2:])
            f_rev = rpm / 60.0
            band = _resonance_band(sweeps, bearings, geometric)
            h = np.arange(shares.size)
            near = (h * f_rev >= band[0]) & (h * f_rev <= band[1])
            harmonics[bearings, rpm] = (shares[1:4].sum(), shares[near].sum(), h[near])
    text = '; '.join(
        f'{b} bearings {rpm:g} rpm: harmonics 1-3 {harmonics[b, rpm][0]:.0%}, harmonics '
        f'{harmonics[b, rpm][2].min()}-{harmonics[b, rpm][2].max()} (near modes 1-2) '
        f'{harmonics[b, rpm][1]:.0%}' for b in BEARINGS for rpm in fs.PAPER_RPM)
    ok = all(harmonics[b, 391.0][1] > 2 * harmonics[b, 269.0][1] for b in BEARINGS)
    slow_pure = all(harmonics[b, 269.0][0] > 0.9 for b in BEARINGS)
    add('Sec. 4.3', 'coupler mid-point: only the drive frequency at 269 rpm, strong '
        'natural-frequency content at 391 rpm', 'variance shares (harmonics 1-3 are the '
        'rigid-body inertia loads): ' + text,
        'agree' if ok and slow_pure else ('partly' if ok else 'disagree'))
    areas = []
    for rpm in fs.PAPER_RPM:
        response = responses['rigid', rpm]
        rigid = _coupler_mid_path(data['mechanism'], response.crank_angle)
        areas.append(fs.signed_area(rigid.real, rigid.imag))
    add('Fig. 22', 'the coupler mid-point path runs counter-clockwise',
        f'signed area of the path {1e4 * areas[0]:.1f} cm^2 with the crank turning '
        'counter-clockwise (positive = counter-clockwise)',
        'agree' if areas[0] > 0 else 'disagree')
    if geometric:
        no_kg = {key: _p2p(r) for key, r in data['no_kg_responses'].items()}
        rows = [f'{b} bearings {rpm:g} rpm coupler mid '
                f'{1e3 * np.hypot(*no_kg[b, rpm][2:]):.2f} -> '
                f'{1e3 * np.hypot(*p2p[b, rpm][2:]):.2f} mm'
                for b in BEARINGS for rpm in fs.PAPER_RPM]
        change = max(abs(np.hypot(*p2p[key][2:]) / np.hypot(*no_kg[key][2:]) - 1)
                     for key in p2p)
        add('Conclusion 1', 'K_G has a very large effect on frequencies and dynamic '
            'deflections', 'peak-to-peak without -> with K_G: ' + '; '.join(rows),
            'agree' if change > 0.2 else ('partly' if change > 0.05 else 'disagree'))
    else:
        add('Conclusion 1', 'K_G has a very large effect on frequencies and deflections',
            'K_G not computed: ' + data['geometric_reason'], 'not computed')
    lowest = [(flex_b.frequencies_hz[:, 0].mean(), rigid_b.frequencies_hz[:, 0].mean())]
    add('Conclusion 3', 'flexible bearings lower the frequencies and raise the deflection at '
        'the link ends', f'mean mode-1 frequency {lowest[0][1]:.2f} -> {lowest[0][0]:.2f} Hz; '
        f'lever tip x{ratio_tip[0]:.0f} at 269 rpm, x{ratio_tip[1]:.0f} at 391 rpm',
        'agree' if lowest[0][0] < lowest[0][1] and min(ratio_tip) > 1 else 'disagree')
    return claims


def _resonance_band(sweeps, bearings, geometric):
    """Frequency band [Hz] of modes 1-2 of the rigid-crank case (+-10 %)."""
    suffix = f'_kg_{fs.PAPER_SPEEDS_RAD_S[-1]:g}' if geometric else ''
    key = ('rigid_crank_bearings' if bearings == 'flexible' else 'rigid_crank') + suffix
    f = sweeps[key].frequencies_hz[:, :2]
    return 0.9 * f.min(), 1.1 * f.max()


def _p2p(response):
    return response.outputs.max(axis=0) - response.outputs.min(axis=0)


def _coupler_mid_path(mechanism, crank_angle):
    """Rigid-body path of the coupler mid-point [m], complex, shape (P,)."""
    state = solve_kinematics(mechanism, crank_angle)
    return state.point(1, 0.5 * mechanism.lengths[2])[0]


# -- charts ------------------------------------------------------------------------------------


def _unit(values_m):
    """Scale and unit label for deflections: micrometres below 0.1 mm, mm otherwise."""
    peak = np.abs(values_m).max() if np.size(values_m) else 0.0
    return (1e6, '\u00b5m') if peak < 1e-4 else (1e3, 'mm')


def _length(value_m):
    """A deflection for people: micrometres below 0.1 mm, millimetres otherwise."""
    scale, unit = _unit(value_m)
    return f'{scale * value_m:.3g} {unit}' if unit != 'mm' else f'{scale * value_m:.3f} mm'


def _mark_events(ax, sweep, mode):
    """Mark a mode's veerings (circle) and swaps (cross) on a frequency axis."""
    for event in sweep.events:
        if mode not in event.modes:
            continue
        k = event.index
        deg = sweep.crank_deg[k]
        if event.kind == 'swap':   # drawn midway, at the mean of the two samples
            k1 = (k + 1) % len(sweep.crank_deg)
            deg = event.parameter % 360.0
            f = 0.5 * (sweep.frequencies_hz[k, mode] + sweep.frequencies_hz[k1, mode])
        else:
            f = sweep.frequencies_hz[k, mode]
        ax.plot([deg], [f], marker='o' if event.kind == 'veering' else 'X', color='black',
                markersize=7, markerfacecolor='none' if event.kind == 'veering' else 'black',
                linestyle='none')


def _event_legend(ax):
    """Legend entries for the event markers."""
    ax.plot([], [], marker='o', color='black', markerfacecolor='none', linestyle='none',
            label='veering (smallest gap)')
    ax.plot([], [], marker='X', color='black', linestyle='none',
            label='order swap between samples')


def plot_fig7(sweep, path):
    """Lowest three frequencies vs crank angle, all flexible, no K_G (Fig. 7)."""
    figure = Figure(figsize=(8.0, 4.8), layout='constrained')
    ax = figure.subplots()
    for m in range(sweep.frequencies_hz.shape[1]):
        f = sweep.frequencies_hz[:, m]
        ax.plot(sweep.crank_deg, f, color=MODE_COLOURS[m],
                label=f'mode {m + 1}: {f.min():.2f}-{f.max():.2f} Hz')
    for m in range(sweep.frequencies_hz.shape[1]):
        _mark_events(ax, sweep, m)
    ax.set_xlim(0, 360)
    ax.set_xticks(np.arange(0, 361, 45))
    ax.set_ylim(0, 1.1 * sweep.frequencies_hz.max())
    ax.set_xlabel('crank angle [deg]')
    ax.set_ylabel('natural frequency [Hz]')
    ax.set_title('Frozen natural frequencies, all links flexible, pins, no geometric '
                 'stiffness (Fig. 7)', fontsize=10)
    ax.grid(True, alpha=0.3)
    if sweep.events:
        _event_legend(ax)
    ax.legend(fontsize=8, loc='center right')
    figure.savefig(path, dpi=DPI)
    return path


def _plot_mode_panels(sweeps, styles, path, title):
    """One panel per mode (1-3), one curve per case."""
    figure = Figure(figsize=(13.0, 4.4), layout='constrained')
    axes = figure.subplots(1, 3)
    for m, ax in enumerate(axes):
        for key, style, colour in styles:
            if key not in sweeps:
                continue
            sweep = sweeps[key]
            ax.plot(sweep.crank_deg, sweep.frequencies_hz[:, m], linestyle=style,
                    color=colour, label=sweep.case.label)
            _mark_events(ax, sweep, m)
        ax.set_title(f'mode {m + 1}')
        ax.set_xlim(0, 360)
        ax.set_xticks(np.arange(0, 361, 90))
        ax.set_xlabel('crank angle [deg]')
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel('natural frequency [Hz]')
    if any(sweeps[key].events for key, _, _ in styles if key in sweeps):
        _event_legend(axes[0])
    handles, labels = axes[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc='outside lower center', ncol=3, fontsize=8)
    figure.suptitle(title, fontsize=10)
    figure.savefig(path, dpi=DPI)
    return path


def plot_fig8_10(sweeps, geometric, path):
    """Modes 1-3: all flexible vs rigid crank, with and without K_G (Figs. 8-10)."""
    styles = [('flex_kg_30', '-', 'tab:blue'), ('flex_kg_45', '-', 'tab:cyan'),
              ('rigid_crank_kg_30', '--', 'tab:red'), ('rigid_crank_kg_45', '--', 'tab:pink'),
              ('flex', '-.', 'black'), ('rigid_crank', ':', 'grey')]
    title = ('Figs. 8-10: all flexible (solid) vs rigid crank (dashed) with K_G at 30 and 45 '
             'rad/s, and without K_G (chain, dotted); pins' if geometric else
             'Figs. 8-10 WITHOUT geometric stiffness (core/dynamics.py not available): '
             'all flexible vs rigid crank; pins')
    return _plot_mode_panels(sweeps, styles, path, title)


def plot_fig11_13(sweeps, geometric, path):
    """Modes 1-3: rigid crank, rigid vs flexible bearings, 30 and 45 rad/s (Figs. 11-13)."""
    if geometric:
        styles = [('rigid_crank_kg_30', '-', 'tab:blue'),
                  ('rigid_crank_bearings_kg_30', '--', 'tab:red'),
                  ('rigid_crank_bearings_kg_45', '-.', 'tab:purple')]
    else:
        styles = [('rigid_crank', '-', 'tab:blue'), ('rigid_crank_bearings', '--', 'tab:red')]
    title = ('Figs. 11-13: rigid crank, pins vs flexible bearings (k = 22.7 kN/m at all four '
             'joints), K_G at 30 and 45 rad/s' if geometric else
             'Figs. 11-13 WITHOUT geometric stiffness (core/dynamics.py not available): rigid '
             'crank, pins vs flexible bearings (k = 22.7 kN/m at all four joints)')
    return _plot_mode_panels(sweeps, styles, path, title)


def plot_mode_shapes(shapes, deg, geometric, path):
    """Lowest three mode shapes at one crank angle, all flexible and rigid crank (Figs. 14-15)."""
    figure = Figure(figsize=(13.0, 7.0), layout='constrained')
    axes = figure.subplots(2, 3, sharex=True, sharey=True)
    for row, (key, name) in enumerate((('flex', 'all flexible'),
                                       ('rigid_crank', 'rigid crank'))):
        data = shapes[key]
        for m in range(3):
            ax = axes[row, m]
            positions = data['positions']
            for link in range(3):
                rigid = positions[link]
                ax.plot(rigid[:, 0] * 1e3, rigid[:, 1] * 1e3, color='0.75', linewidth=1.0)
                bent = rigid + SHAPE_SCALE * data['deflection'][m, link]
                ax.plot(bent[:, 0] * 1e3, bent[:, 1] * 1e3, color=LINK_COLOURS[link],
                        linewidth=2.0, label=LINK_NAMES[link])
            share = data['strain_share'][m]
            ax.set_title(f'({"abc"[m] if row == 0 else "def"[m]}) {name}, mode {m + 1}: '
                         f'{data["frequencies_hz"][m]:.1f} Hz\nstrain energy: crank '
                         f'{share[0]:.0%}, coupler {share[1]:.0%}, lever {share[2]:.0%}',
                         fontsize=9)
            ax.set_aspect('equal')
            ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel('X [mm]')
    for ax in axes[:, 0]:
        ax.set_ylabel('Y [mm]')
    axes[0, 0].legend(fontsize=8, loc='upper left')
    figure.suptitle(f'Mode shapes at crank angle {deg:g} deg (Fig. {14 if deg < 90 else 15}): '
                    f'mass-normalised x {SHAPE_SCALE:g} m/sqrt(kg) as in the paper; grey = '
                    f'undeformed; pins, '
                    + (f'K_G at {SHAPE_SPEED_RAD_S:g} rad/s' if geometric
                       else 'no K_G (core/dynamics.py not available)'), fontsize=10)
    figure.savefig(path, dpi=DPI)
    return path


def _exaggeration(deflection, reference_length):
    """A round factor making the largest deflection about 5 % of reference_length."""
    peak = np.abs(deflection).max()
    raw = 0.05 * reference_length / max(peak, 1e-12)
    for factor in (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000):
        if factor >= raw:
            return factor
    return 1000


def plot_deflected_linkage(linkage, mechanism, geometric, path):
    """The deflected linkage every 3 degrees at 30 rad/s in four quarter turns (Figs. 16-19)."""
    deg = linkage['crank_deg']
    positions, deflection = linkage['positions'], linkage['deflection']
    factor = _exaggeration(deflection, mechanism.lengths[2])
    figure = Figure(figsize=(12.0, 9.0), layout='constrained')
    axes = figure.subplots(2, 2, sharex=True, sharey=True)
    cmap = colormaps['viridis']
    for ax, (start, stop), fig in zip(axes.ravel(), QUARTERS_DEG, (16, 17, 18, 19)):
        chosen = [k for k, d in enumerate(deg)
                  if (d - start) % 360.0 <= (stop - start) + 1e-9 and
                  np.isclose((d - start) % 3.0, 0.0, atol=1e-6)]
        chosen.sort(key=lambda k: (deg[k] - start) % 360.0)   # in order of travel
        for rank, k in enumerate(chosen):
            colour = cmap(rank / max(len(chosen) - 1, 1))
            for link in range(3):
                shape = positions[k, link] + factor * deflection[k, link]
                ax.plot(shape[:, 0] * 1e3, shape[:, 1] * 1e3, color=colour, linewidth=0.8)
        ground = np.array([0.0, mechanism.ground_length]) * 1e3
        ax.plot(ground, [0.0, 0.0], 'k^', markersize=9)
        ax.set_title(f'crank {start:g} to {stop % 360:g} deg (Fig. {fig}); colour: '
                     f'early (purple) to late (yellow)', fontsize=9)
        ax.set_aspect('equal')
        ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel('X [mm]')
    for ax in axes[:, 0]:
        ax.set_ylabel('Y [mm]')
    coupler = np.abs(deflection[:, 1]).max()
    figure.suptitle(f'Deflected linkage every 3 deg at {SHAPE_SPEED_RAD_S:g} rad/s, all links '
                    f'flexible, pins, ' + ('K_G on' if geometric else 'no K_G') +
                    f': deflections x {factor} (largest true coupler deflection '
                    f'{1e3 * coupler:.2f} mm)', fontsize=10)
    figure.savefig(path, dpi=DPI)
    return path


def plot_point_deflections(responses, columns, name, fig, geometric, path):
    """X (solid) and Y (dashed) deflection of one point, bearings x speeds (Figs. 20-21)."""
    figure = Figure(figsize=(11.0, 7.0), layout='constrained')
    axes = figure.subplots(2, 2, sharex=True)
    for row, bearings in enumerate(BEARINGS):
        for col, rpm in enumerate(fs.PAPER_RPM):
            ax = axes[row, col]
            response = responses[bearings, rpm]
            deg = np.mod(np.degrees(response.crank_angle), 360.0)
            order = np.argsort(deg)
            values = response.outputs[:, columns]
            scale, unit = _unit(values)
            p2p = values.max(axis=0) - values.min(axis=0)
            # one periodic revolution: repeat the first sample at +360 degrees
            deg_closed = np.append(deg[order], deg[order[0]] + 360.0)
            closed = np.vstack([values[order], values[order[:1]]])
            ax.plot(deg_closed, scale * closed[:, 0], color='tab:blue', label='X')
            ax.plot(deg_closed, scale * closed[:, 1], color='tab:red', linestyle='--',
                    label='Y')
            ax.set_title(f'({"abcd"[2 * row + col]}) {bearings} bearings, {rpm:g} rpm: '
                         f'peak-to-peak X {scale * p2p[0]:.3g}, Y {scale * p2p[1]:.3g} {unit}',
                         fontsize=9)
            ax.set_ylabel(f'deflection [{unit}]')
            ax.set_xlim(0, 360)
            ax.set_xticks(np.arange(0, 361, 60))
            ax.axhline(0.0, color='0.6', linewidth=0.6)
            ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel('crank angle [deg]')
    axes[0, 0].legend(fontsize=8)
    figure.suptitle(f'{name}: ground-frame elastic deflection (Fig. {fig}); rigid crank, '
                    + ('K_G on' if geometric else 'no K_G') + ', zeta = 0.02, full order; '
                    'note the different scales', fontsize=10)
    figure.savefig(path, dpi=DPI)
    return path


def plot_coupler_path(responses, mechanism, path):
    """Coupler mid-point paths, rigid and flexible (Fig. 22), and the deflection loops."""
    figure = Figure(figsize=(12.0, 9.5), layout='constrained')
    axes = figure.subplots(2, 2)
    styles = {'rigid': ('tab:blue', 'flexible links, pins'),
              'flexible': ('tab:red', 'flexible links and bearings')}
    for col, rpm in enumerate(fs.PAPER_RPM):
        ax, loop = axes[0, col], axes[1, col]
        angles = responses['rigid', rpm].crank_angle
        rigid = _coupler_mid_path(mechanism, angles)
        closed = np.append(rigid, rigid[0])
        ax.plot(closed.real * 1e3, closed.imag * 1e3, 'k--', linewidth=1.2, label='rigid')
        for bearings in BEARINGS:
            out = responses[bearings, rpm].outputs[:, 2:]
            moved = rigid + out[:, 0] + 1j * out[:, 1]
            moved = np.append(moved, moved[0])
            colour, label = styles[bearings]
            ax.plot(moved.real * 1e3, moved.imag * 1e3, color=colour, linewidth=1.0,
                    label=label)
            loop_closed = np.vstack([out, out[:1]]) * 1e3
            loop.plot(loop_closed[:, 0], loop_closed[:, 1], color=colour, label=label)
            loop.plot(*loop_closed[0], 'o', color=colour, markersize=5)
        state = solve_kinematics(mechanism, 0.0)
        joints = [state.joints[j][0] for j in ('O2', 'A', 'B', 'O4')]
        ax.plot([z.real * 1e3 for z in joints], [z.imag * 1e3 for z in joints], color='0.5',
                marker='o', linewidth=1.5, label='rigid linkage at 0 deg')
        span = max(len(rigid) // 15, 1)   # about 24 degrees of crank
        for k in (len(rigid) // 8, 5 * len(rigid) // 8):
            ax.annotate('', xy=(rigid[k + span].real * 1e3, rigid[k + span].imag * 1e3),
                        xytext=(rigid[k].real * 1e3, rigid[k].imag * 1e3),
                        arrowprops={'arrowstyle': '-|>', 'color': 'black', 'lw': 1.5,
                                    'mutation_scale': 15, 'shrinkA': 0, 'shrinkB': 0})
        ax.set_title(f'{rpm:g} rpm: coupler mid-point path (true scale)', fontsize=9)
        ax.set_aspect('equal')
        ax.set_xlabel('X [mm]')
        ax.set_ylabel('Y [mm]')
        ax.grid(True, alpha=0.3)
        loop.set_title(f'{rpm:g} rpm: elastic deflection of the coupler mid-point '
                       '(dot = crank 0 deg)', fontsize=9)
        loop.set_aspect('equal', adjustable='datalim')
        loop.set_xlabel('dX [mm]')
        loop.set_ylabel('dY [mm]')
        loop.grid(True, alpha=0.3)
    for ax in axes[0]:
        low, high = ax.get_ylim()
        ax.set_ylim(low, high + 0.25 * (high - low))
    axes[0, 0].legend(fontsize=8, loc='upper left')
    axes[1, 0].legend(fontsize=8)
    figure.suptitle('Fig. 22: coupler mid-point paths, rigid crank, full order (arrow: '
                    'direction of travel)', fontsize=10)
    figure.savefig(path, dpi=DPI)
    return path


def plot_truncation(truncation, path):
    """Relative RMS error of mode superposition vs N (both speeds and bearing models)."""
    figure = Figure(figsize=(12.0, 8.0), layout='constrained')
    axes = figure.subplots(2, 2, sharey=True)
    floor = 1e-6
    for row, bearings in enumerate(BEARINGS):
        for col, rpm in enumerate(fs.PAPER_RPM):
            ax = axes[row, col]
            study = truncation[bearings, rpm]
            for key, style, text in (('plain', '--', 'modes only'),
                                     ('static', '-', 'with static correction')):
                for o, (name, colour) in enumerate((('lever tip', 'tab:red'),
                                                    ('coupler mid-point', 'tab:blue'))):
                    ax.plot(study['modes'], np.maximum(study[key][:, o], floor), style,
                            color=colour, marker='o', markersize=3,
                            label=f'{name}, {text}')
            for tol in fs.TOLERANCES:
                ax.axhline(tol, color='0.4', linewidth=0.8, linestyle=':')
                ax.text(study['modes'][-1], tol, f'{tol:.0%}', va='bottom', ha='right',
                        fontsize=8, color='0.3')
            ax.set_yscale('log')
            ax.set_ylim(floor * 0.7, 2.0)
            ax.set_title(f'{bearings} bearings, {rpm:g} rpm ({study["steps"]} steps/rev)',
                         fontsize=9)
            ax.grid(True, which='both', alpha=0.3)
            ax.set_xlabel('number of frozen modes N')
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    for ax in axes[:, 0]:
        ax.set_ylabel('relative RMS error vs full order')
    handles, labels = axes[0, 0].get_legend_handles_labels()
    figure.legend(handles, labels, loc='outside lower center', ncol=4, fontsize=8)
    figure.suptitle('Modal truncation: mode superposition vs the full-order periodic response '
                    '(rigid crank, same integrator and step; errors below 1e-6 drawn at 1e-6)',
                    fontsize=10)
    figure.savefig(path, dpi=DPI)
    return path


# -- text --------------------------------------------------------------------------------------


def report_text(data):
    """Markdown with every number of the section."""
    step = SWEEP_STEP_DEG[1 if data['quick'] else 0]
    lines = []
    if data['geometric']:
        lines.append('Geometric stiffness (A.4) is included where the paper includes it '
                     '(axial forces from core/dynamics.py).')
    else:
        lines.append(f'**Computed without geometric stiffness**: {data["geometric_reason"]}. '
                     'The K_G cases of Figs. 8-13 are missing, and every other result (mode '
                     'shapes, deflections, truncation) is computed without K_G.')
    mech = data['mechanism']
    lines += ['', f'Model: {mech.elements_per_link} beam elements per link, gravity '
              f'{tuple(mech.gravity)} m/s^2, modal damping zeta = {mech.damping_ratio:g}, '
              f'flexible bearings k = {mech.bearing_stiffness / 1e3:g} kN/m at '
              f'{", ".join(mech.bearing_joints)}, '
              + ('clamped input shaft.' if mech.shaft_stiffness is None
                 else f'input shaft k_t = {mech.shaft_stiffness:g} N m/rad.'),
              '', '### Frozen natural frequencies over the cycle [Hz]', '',
              '| case | mode 1 | mode 2 | mode 3 |', '|---|---|---|---|']
    for sweep in data['sweeps'].values():
        cells = []
        for m in range(3):
            f = sweep.frequencies_hz[:, m]
            links = sorted({LINK_NAMES[i] for i in sweep.dominant_link[:, m]})
            cells.append(f'{f.min():.2f}-{f.max():.2f} ({"/".join(links)})')
        lines.append(f'| {sweep.case.label} | ' + ' | '.join(cells) + ' |')
    lines += ['', '(in brackets: the link holding most strain energy somewhere in the cycle)',
              '', '### Mode veering and order swaps (modes 1-3, '
              f'{step:g}-degree sweep)', '']
    events = [(s.case.label, e) for s in data['sweeps'].values() for e in s.events]
    if events:
        lines += ['| case | kind | modes | crank [deg] | gap at the samples [Hz] | '
                  'smallest gap [Hz] (at deg) | exchange MAC |', '|---|---|---|---|---|---|---|']
        lines += [f'| {label} | {e.kind} | {e.modes[0] + 1}-{e.modes[1] + 1} | '
                  f'{e.parameter % 360:.1f} | {e.gap:.3f} | {e.refined_gap:.4f} '
                  f'({e.refined_parameter:.2f}) | {e.exchange:.2f} |' for label, e in events]
        lines += ['', f'A swap is an order change between {step:g}-degree samples; the '
                  'refined smallest gap says whether the modes truly cross (gap 0) or veer '
                  'sharply.']
    else:
        gaps = []
        for sweep in data['sweeps'].values():
            f = sweep.frequencies_hz
            gaps.append(f'{sweep.case.label}: modes 1-2 {np.min(f[:, 1] - f[:, 0]):.2f} Hz, '
                        f'2-3 {np.min(f[:, 2] - f[:, 1]):.2f} Hz')
        lines += ['None: no veering and no order swap among modes 1-3 in any case. Smallest '
                  'gaps: ' + '; '.join(gaps) + '.']
    lines += ['', '### Peak-to-peak elastic deflections (rigid crank, full order)', '',
              '| bearings | rpm | lever tip X | lever tip Y | coupler mid X | coupler mid Y |',
              '|---|---|---|---|---|---|']
    for (bearings, rpm), response in data['responses'].items():
        p2p = _p2p(response)
        lines.append(f'| {bearings} | {rpm:g} | ' + ' | '.join(_length(v) for v in p2p) + ' |')
    lines += ['', '### Modes needed for a relative RMS error (mode superposition vs full '
              'order, rigid crank)', '',
              '| bearings | rpm | steps/rev | output | 1 % | 5 % | 1 % static corr. | '
              '5 % static corr. | error with all modes |', '|---|---|---|---|---|---|---|---|---|']
    for (bearings, rpm), study in data['truncation'].items():
        for o, name in enumerate(('lever tip', 'coupler mid')):
            cells = [fs.modes_needed(study['modes'], study[key][:, o], tol)
                     for key in ('plain', 'static') for tol in fs.TOLERANCES]
            cells = ['none' if c is None else str(c) for c in cells]
            lines.append(f'| {bearings} | {rpm:g} | {study["steps"]} | {name} | '
                         + ' | '.join(cells) + f' | {study["static"][-1, o]:.1e} |')
    lines += ['', f'Total DOFs: rigid bearings {data["truncation"]["rigid", 269.0]["modes"][-1]}, '
              f'flexible {data["truncation"]["flexible", 269.0]["modes"][-1]}. "Needed" means '
              'every larger N tried also meets the target. Modal runs with flexible bearings '
              'use finer steps: their step-to-step basis transfer loses a few percent at 720 '
              'steps/rev whatever N is (a plateau in the chart).',
              '', '### Paper claims (Sec. 4 and conclusions) against this model', '',
              '| where | paper says | we measure | verdict |', '|---|---|---|---|']
    for claim in data['claims']:
        lines.append(f'| {claim["where"]} | {claim["claim"]} | {claim["measured"]} | '
                     f'**{claim["verdict"]}** |')
    lines += ['', 'Compute time: ' + ', '.join(f'{k} {v:.1f} s'
                                                for k, v in data['seconds'].items()) + '.']
    return '\n'.join(lines)


def plot_flex(out_dir, quick=False, data=None):
    """
    Report section: frozen modes, deflections, paths and truncation of Cho 1992.

    Parameters
    ----------
    out_dir : str or pathlib.Path
        Directory (created if missing).
    quick : bool
        Reduced sizes (2 elements per link, 10-degree sweeps, few steps) for tests.
    data : dict or None
        A :func:`compute_flex` result to draw (computed with ``quick`` if None).

    Returns
    -------
    dict
        'charts' (list of pathlib.Path) and 'text' (markdown with the numbers).

    """
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if data is None:
        data = compute_flex(quick=quick)
    mechanism, geometric, sweeps = data['mechanism'], data['geometric'], data['sweeps']
    charts = [plot_fig7(sweeps['flex'], out / 'flex_frequencies_fig7.png'),
              plot_fig8_10(sweeps, geometric, out / 'flex_frequencies_fig8_10.png'),
              plot_fig11_13(sweeps, geometric, out / 'flex_frequencies_fig11_13.png')]
    for deg in SHAPE_ANGLES_DEG:
        charts.append(plot_mode_shapes(data['shapes'][deg], deg, geometric,
                                       out / f'flex_mode_shapes_{deg:g}deg.png'))
    charts.append(plot_deflected_linkage(data['linkage'], mechanism, geometric,
                                         out / 'flex_deflected_linkage.png'))
    charts.append(plot_point_deflections(data['responses'], slice(0, 2),
                                         'Lever tip (upper end of the lever)', 20, geometric,
                                         out / 'flex_lever_tip.png'))
    charts.append(plot_point_deflections(data['responses'], slice(2, 4), 'Coupler mid-point',
                                         21, geometric, out / 'flex_coupler_mid.png'))
    charts.append(plot_coupler_path(data['responses'], mechanism, out / 'flex_coupler_path.png'))
    charts.append(plot_truncation(data['truncation'], out / 'flex_truncation.png'))
    return {'charts': charts, 'text': report_text(data)}


__all__ = ['compute_flex', 'compare_claims', 'report_text', 'plot_flex', 'plot_fig7',
           'plot_fig8_10', 'plot_fig11_13', 'plot_mode_shapes', 'plot_deflected_linkage',
           'plot_point_deflections', 'plot_coupler_path', 'plot_truncation']
