"""
The qualitative claims of Cho, Park & Lee (1992), Sec. 4 and conclusions, against our numbers.

One function per claim (:data:`CLAIMS`, in the paper's order), each reading the result of
:func:`studies.flex_data.compute_flex` and returning ``{'where', 'claim', 'measured',
'verdict'}`` with the verdict 'agree', 'disagree' or 'partly'.
"""

import numpy as np

from .flex_frequencies import BEARINGS, PAPER_RPM, PAPER_SPEEDS_RAD_S, SHAPE_ANGLES_DEG
from .flex_measures import coupler_mid_path, harmonic_shares, peak_to_peak
from .flex_measures import shape_correlation, signed_area, uniform_load_shape
from ..names import LINK_NAMES

# The link holding modes 1, 2, 3 according to Conclusion 2: coupler, lever, crank.
CONCLUSION_2_LINKS = (1, 2, 0)


def _claim(where, claim, measured, verdict):
    return {'where': where, 'claim': claim, 'measured': measured, 'verdict': verdict}


def _variation(sweep, mode):
    """(min, max, max - min) of a mode's frequency over the cycle [Hz]."""
    f = sweep.frequencies_hz[:, mode]
    return f.min(), f.max(), f.max() - f.min()


def _kg_sweep(sweeps, key, speed=PAPER_SPEEDS_RAD_S[0]):
    """Return the sweep of a case with K_G at ``speed`` [rad/s]."""
    return sweeps[f'{key}_kg_{speed:g}']


def claim_fig7(data):
    """Fig. 7: without K_G modes 1 and 2 vary little over the cycle, mode 3 a lot."""
    spans = [_variation(data['sweeps']['flex'], m)[2] for m in range(3)]
    return _claim('Fig. 7', 'without K_G, modes 1 and 2 vary little over the cycle, mode 3 a lot',
                  'variation (max-min) ' + ', '.join(f'mode {m + 1}: {s:.2f} Hz'
                                                     for m, s in enumerate(spans)),
                  'agree' if spans[2] > 5 * max(spans[:2]) else 'disagree')


def claim_kg_variation(data):
    """Figs. 8-9: K_G widens the variation of modes 1-2, more with all links flexible."""
    sweeps = data['sweeps']
    speed = PAPER_SPEEDS_RAD_S[0]
    kg, kg_rc = _kg_sweep(sweeps, 'flex', speed), _kg_sweep(sweeps, 'rigid_crank', speed)
    flex, rc = sweeps['flex'], sweeps['rigid_crank']
    rows, ok_kg, ok_flex = [], True, True
    for m in range(2):
        a, b, c, d = (_variation(s, m)[2] for s in (kg, kg_rc, flex, rc))
        rows.append(f'mode {m + 1}: all flexible {c:.2f} -> {a:.2f} Hz, rigid crank '
                    f'{d:.2f} -> {b:.2f} Hz')
        ok_kg &= a > c and b > d
        ok_flex &= a > b
    verdict = 'agree' if ok_kg and ok_flex else ('partly' if ok_kg or ok_flex else 'disagree')
    return _claim('Figs. 8-9', 'K_G widens the variation of modes 1-2, more with all links '
                  'flexible than with a rigid crank', f'variation without -> with K_G at '
                  f'{speed:g} rad/s: ' + '; '.join(rows), verdict)


def claim_fig10(data):
    """Fig. 10: for mode 3 K_G matters little, crank flexibility a lot."""
    sweeps = data['sweeps']
    kg, kg_rc = _kg_sweep(sweeps, 'flex'), _kg_sweep(sweeps, 'rigid_crank')
    shift_kg = np.abs(kg.frequencies_hz[:, 2] - sweeps['flex'].frequencies_hz[:, 2]).max()
    shift_crank = np.abs(kg_rc.frequencies_hz[:, 2] - kg.frequencies_hz[:, 2]).max()
    return _claim('Fig. 10', 'mode 3: K_G matters little, crank flexibility a lot',
                  f'max shift by K_G {shift_kg:.2f} Hz, by a rigid crank {shift_crank:.1f} Hz',
                  'agree' if shift_crank > 5 * shift_kg else 'disagree')


def _bearing_sweeps(sweeps):
    """Rigid-crank sweeps with K_G at 30 rad/s: (rigid bearings, flexible bearings)."""
    return _kg_sweep(sweeps, 'rigid_crank'), _kg_sweep(sweeps, 'rigid_crank_bearings')


def claim_bearings_lower_frequencies(data):
    """Figs. 11-13: flexible bearings lower the frequencies of all three modes."""
    rigid_b, flex_b = _bearing_sweeps(data['sweeps'])
    drops = flex_b.frequencies_hz - rigid_b.frequencies_hz
    return _claim('Figs. 11-13', 'flexible bearings lower the frequencies of all three modes',
                  'flexible minus rigid bearings, over the cycle: ' + ', '.join(
                      f'mode {m + 1} {drops[:, m].min():.1f} to {drops[:, m].max():.1f} Hz'
                      for m in range(3)) + ' (springs at all four joints)',
                  'agree' if np.all(drops < 0) else 'disagree')


def claim_speed_widens_variation(data):
    """Figs. 11-13: a higher speed widens the variation, most in modes 1-2."""
    slow = _kg_sweep(data['sweeps'], 'rigid_crank_bearings', PAPER_SPEEDS_RAD_S[0])
    fast = _kg_sweep(data['sweeps'], 'rigid_crank_bearings', PAPER_SPEEDS_RAD_S[1])
    growth = [_variation(fast, m)[2] / max(_variation(slow, m)[2], 1e-12) for m in range(3)]
    return _claim('Figs. 11-13', 'higher speed (45 vs 30 rad/s) widens the variation, most in '
                  'modes 1-2', 'variation ratio 45/30 rad/s: ' + ', '.join(
                      f'mode {m + 1} {g:.2f}' for m, g in enumerate(growth)),
                  'agree' if min(growth[:2]) > 1 and max(growth[:2]) > growth[2] else
                  ('partly' if max(growth) > 1 else 'disagree'))


def claim_shapes_change(data):
    """Figs. 14-15: crank flexibility changes the mode shapes, mode 3 most."""
    shapes = data['shapes']
    macs = {deg: np.diag(shapes[deg]['mac']) for deg in SHAPE_ANGLES_DEG}
    swapped = [d for d in SHAPE_ANGLES_DEG
               if min(shapes[d]['mac'][0, 1], shapes[d]['mac'][1, 0]) > 0.5]
    return _claim(
        'Figs. 14-15', 'crank flexibility changes the mode shapes, mode 3 most',
        'MAC of all-flexible vs rigid-crank modes on coupler and lever: ' + '; '.join(
            f'{deg:g} deg: ' + ', '.join(f'{v:.2f}' for v in macs[deg])
            for deg in SHAPE_ANGLES_DEG) + ''.join(
            f'; at {d:g} deg modes 1 and 2 trade places between the models (cross MAC '
            f'{shapes[d]["mac"][0, 1]:.2f}, {shapes[d]["mac"][1, 0]:.2f})' for d in swapped),
        'agree' if all(macs[d][2] < min(macs[d][:2]) for d in SHAPE_ANGLES_DEG) else 'partly')


def _dominated(shapes, deg, key):
    """Dominant link of each mode with its strain-energy share, as text."""
    model = shapes[deg][key]
    return ', '.join(f'{LINK_NAMES[i]} ({model["strain_share"][m, i]:.0%})'
                     for m, i in enumerate(model['dominant']))


def _dominant_names(shapes, key):
    return {deg: [LINK_NAMES[i] for i in shapes[deg][key]['dominant']]
            for deg in SHAPE_ANGLES_DEG}


def claim_dominant_all_flexible(data):
    """Sec. 4.2: all flexible, mode 1 is the lever at 27 deg and the coupler at 123 deg."""
    shapes = data['shapes']
    names = _dominant_names(shapes, 'flex')
    paper = {27.0: ['lever', 'coupler'], 123.0: ['coupler', 'lever']}
    matches = [names[d][:2] == paper[d] for d in SHAPE_ANGLES_DEG]
    return _claim('Sec. 4.2', 'all flexible: at 27 deg mode 1 is the lever, mode 2 the '
                  'coupler; at 123 deg mode 1 the coupler, mode 2 the lever', '; '.join(
                      f'{d:g} deg: modes 1-3 dominated by ' + _dominated(shapes, d, 'flex')
                      for d in SHAPE_ANGLES_DEG) + ' (strain-energy share)',
                  'agree' if all(matches) else ('partly' if any(matches) else 'disagree'))


def claim_dominant_rigid_crank(data):
    """Sec. 4.2: with a rigid crank mode 1 is the coupler, mode 2 the lever."""
    shapes = data['shapes']
    names = _dominant_names(shapes, 'rigid_crank')
    ok = all(names[d][:2] == ['coupler', 'lever'] for d in SHAPE_ANGLES_DEG)
    return _claim('Sec. 4.2', 'rigid crank: mode 1 is the coupler, mode 2 the lever', '; '.join(
        f'{d:g} deg: ' + _dominated(shapes, d, 'rigid_crank') for d in SHAPE_ANGLES_DEG),
        'agree' if ok else 'disagree')


def claim_mode_order(data):
    """Conclusion 2: mode 1 is the coupler, mode 2 the lever, mode 3 the crank."""
    dominant = data['sweeps']['flex'].dominant_link
    share = [(dominant[:, m] == link).mean() for m, link in enumerate(CONCLUSION_2_LINKS)]
    claim = _claim('Conclusion 2', 'mode 1 is the coupler, mode 2 the lever, mode 3 the crank',
                   'share of the cycle where it holds (all flexible, pins, no K_G): ' + ', '.join(
                       f'mode {m + 1} {s:.0%}' for m, s in enumerate(share)),
                   'agree' if min(share) > 0.9 else ('partly' if max(share) > 0.5
                                                     else 'disagree'))
    kg = _kg_sweep(data['sweeps'], 'flex').dominant_link
    share_kg = [(kg[:, m] == link).mean() for m, link in enumerate(CONCLUSION_2_LINKS)]
    claim['measured'] += '; with K_G at 30 rad/s: ' + ', '.join(
        f'mode {m + 1} {s:.0%}' for m, s in enumerate(share_kg))
    if min(share_kg) <= 0.9 and claim['verdict'] == 'agree':
        claim['verdict'] = 'partly'
    return claim


def claim_bending_shape(data):
    """Figs. 16-19: coupler and lever bend like simply supported beams under uniform load."""
    link = data['linkage']
    s, bending = link['bending'][1]
    template = uniform_load_shape(s)
    peak = np.abs(bending).max(axis=1).argmax()
    corr = {name: abs(shape_correlation(link['bending'][i][1][peak], template)[0])
            for i, name in ((1, 'coupler'), (2, 'lever'))}
    crank = np.abs(link['deflection'][:, 0]).max()
    coupler = np.abs(link['deflection'][:, 1]).max()
    return _claim(
        'Figs. 16-19', 'coupler and lever bend like simply supported beams under distributed '
        'load; the crank deflects too little to see',
        f'correlation with the uniform-load shape at the largest coupler bending '
        f'({link["crank_deg"][peak] % 360:.0f} deg): coupler {corr["coupler"]:.3f}, lever '
        f'{corr["lever"]:.3f}; largest crank deflection {1e6 * crank:.1f} \u00b5m vs coupler '
        f'{1e3 * coupler:.2f} mm', 'agree' if min(corr.values()) > 0.95 and
        crank < 0.05 * coupler else 'partly')


def _peak_to_peaks(data):
    return {key: peak_to_peak(r) for key, r in data['responses'].items()}


def _tip_ratios(p2p):
    """Lever-tip peak-to-peak, flexible over rigid bearings, per paper speed."""
    return [np.hypot(*p2p['flexible', rpm][:2]) / np.hypot(*p2p['rigid', rpm][:2])
            for rpm in PAPER_RPM]


def claim_lever_tip(data):
    """Fig. 20: the lever tip moves little with rigid bearings, a lot with flexible ones."""
    p2p = _peak_to_peaks(data)
    ratio_tip = _tip_ratios(p2p)
    return _claim('Fig. 20', 'lever tip: tiny with rigid bearings, relatively very large with '
                  'flexible', ', '.join(
                      f'{rpm:g} rpm: {1e6 * np.hypot(*p2p["rigid", rpm][:2]):.1f} \u00b5m vs '
                      f'{1e3 * np.hypot(*p2p["flexible", rpm][:2]):.2f} mm (x{r:.0f})'
                      for rpm, r in zip(PAPER_RPM, ratio_tip))
                  + ' (peak-to-peaks combined as hypot(X, Y))',
                  'agree' if min(ratio_tip) > 10 else 'disagree')


def claim_coupler_mid(data):
    """Fig. 21: bearing flexibility changes the coupler mid-point deflection little."""
    p2p = _peak_to_peaks(data)
    ratio_mid = [np.hypot(*p2p['flexible', rpm][2:]) / np.hypot(*p2p['rigid', rpm][2:])
                 for rpm in PAPER_RPM]
    ratio_b = [np.hypot(*peak_to_peak(data['b_only_responses'][rpm])[2:])
               / np.hypot(*p2p['rigid', rpm][2:]) for rpm in PAPER_RPM]
    return _claim(
        'Fig. 21', 'coupler mid-point: bearing flexibility changes it little',
        'flexible / rigid bearings, peak-to-peaks combined as hypot(X, Y): ' + ', '.join(
            f'{rpm:g} rpm x{r:.2f}' for rpm, r in zip(PAPER_RPM, ratio_mid))
        + ' (springs at all four joints); with the spring at B only: ' + ', '.join(
            f'{rpm:g} rpm x{r:.2f}' for rpm, r in zip(PAPER_RPM, ratio_b)),
        'agree' if max(abs(r - 1) for r in ratio_mid) < 0.25 else
        ('partly' if min(abs(r - 1) for r in ratio_mid) < 0.25 else 'disagree'))


def resonance_band(sweeps, bearings):
    """
    Frequency band [Hz] of modes 1-2 of the rigid-crank case with K_G at 45 rad/s (+-10 %).

    Parameters
    ----------
    sweeps : dict of str to Sweep
        The sweeps of :func:`studies.flex_frequencies.paper_frequency_cases`.
    bearings : str
        'rigid' or 'flexible'.

    Returns
    -------
    tuple of float

    """
    key = 'rigid_crank_bearings' if bearings == 'flexible' else 'rigid_crank'
    f = _kg_sweep(sweeps, key, PAPER_SPEEDS_RAD_S[-1]).frequencies_hz[:, :2]
    return 0.9 * f.min(), 1.1 * f.max()


def claim_harmonics(data):
    """Sec. 4.3: only the drive frequency at 269 rpm, natural frequencies at 391 rpm."""
    harmonics = {}
    for bearings in BEARINGS:
        for rpm in PAPER_RPM:
            shares = harmonic_shares(data['responses'][bearings, rpm].outputs[:, 2:])
            f_rev = rpm / 60.0
            band = resonance_band(data['sweeps'], bearings)
            h = np.arange(shares.size)
            near = (h * f_rev >= band[0]) & (h * f_rev <= band[1])
            harmonics[bearings, rpm] = (shares[1:4].sum(), shares[near].sum(), h[near])
    text = '; '.join(
        f'{b} bearings {rpm:g} rpm: harmonics 1-3 {harmonics[b, rpm][0]:.0%}, harmonics '
        f'{harmonics[b, rpm][2].min()}-{harmonics[b, rpm][2].max()} (near modes 1-2) '
        f'{harmonics[b, rpm][1]:.0%}' for b in BEARINGS for rpm in PAPER_RPM)
    ok = all(harmonics[b, 391.0][1] > 2 * harmonics[b, 269.0][1] for b in BEARINGS)
    slow_pure = all(harmonics[b, 269.0][0] > 0.9 for b in BEARINGS)
    return _claim('Sec. 4.3', 'coupler mid-point: only the drive frequency at 269 rpm, strong '
                  'natural-frequency content at 391 rpm', 'variance shares (harmonics 1-3 are '
                  'the rigid-body inertia loads): ' + text,
                  'agree' if ok and slow_pure else ('partly' if ok else 'disagree'))


def claim_path_direction(data):
    """Fig. 22: the coupler mid-point path runs counter-clockwise."""
    areas = []
    for rpm in PAPER_RPM:
        response = data['responses']['rigid', rpm]
        rigid = coupler_mid_path(data['mechanism'], response.crank_angle)
        areas.append(signed_area(rigid.real, rigid.imag))
    return _claim('Fig. 22', 'the coupler mid-point path runs counter-clockwise',
                  f'signed area of the path {1e4 * areas[0]:.1f} cm^2 with the crank turning '
                  'counter-clockwise (positive = counter-clockwise)',
                  'agree' if areas[0] > 0 else 'disagree')


def claim_kg_effect(data):
    """Conclusion 1: K_G has a very large effect on frequencies and dynamic deflections."""
    p2p = _peak_to_peaks(data)
    no_kg = {key: peak_to_peak(r) for key, r in data['no_kg_responses'].items()}
    rows = [f'{b} bearings {rpm:g} rpm coupler mid '
            f'{1e3 * np.hypot(*no_kg[b, rpm][2:]):.2f} -> '
            f'{1e3 * np.hypot(*p2p[b, rpm][2:]):.2f} mm'
            for b in BEARINGS for rpm in PAPER_RPM]
    change = max(abs(np.hypot(*p2p[key][2:]) / np.hypot(*no_kg[key][2:]) - 1) for key in p2p)
    return _claim('Conclusion 1', 'K_G has a very large effect on frequencies and dynamic '
                  'deflections', 'peak-to-peak without -> with K_G: ' + '; '.join(rows),
                  'agree' if change > 0.2 else ('partly' if change > 0.05 else 'disagree'))


def claim_bearings_conclusion(data):
    """Conclusion 3: flexible bearings lower the frequencies and raise end deflections."""
    rigid_b, flex_b = _bearing_sweeps(data['sweeps'])
    ratio_tip = _tip_ratios(_peak_to_peaks(data))
    lowest = [(flex_b.frequencies_hz[:, 0].mean(), rigid_b.frequencies_hz[:, 0].mean())]
    return _claim('Conclusion 3', 'flexible bearings lower the frequencies and raise the '
                  'deflection at the link ends', f'mean mode-1 frequency {lowest[0][1]:.2f} -> '
                  f'{lowest[0][0]:.2f} Hz; lever tip x{ratio_tip[0]:.0f} at 269 rpm, '
                  f'x{ratio_tip[1]:.0f} at 391 rpm',
                  'agree' if lowest[0][0] < lowest[0][1] and min(ratio_tip) > 1
                  else 'disagree')


# In the order of the paper (and of the report's table).
CLAIMS = (claim_fig7, claim_kg_variation, claim_fig10, claim_bearings_lower_frequencies,
          claim_speed_widens_variation, claim_shapes_change, claim_dominant_all_flexible,
          claim_dominant_rigid_crank, claim_mode_order, claim_bending_shape, claim_lever_tip,
          claim_coupler_mid, claim_harmonics, claim_path_direction, claim_kg_effect,
          claim_bearings_conclusion)


def compare_claims(data):
    """
    Judge each claim of Cho 1992 Sec. 4 and conclusions against our numbers.

    Parameters
    ----------
    data : dict
        A :func:`studies.flex_data.compute_flex` result (without its 'claims').

    Returns
    -------
    list of dict
        'where', 'claim', 'measured', 'verdict' ('agree', 'disagree' or 'partly').

    """
    return [claim(data) for claim in CLAIMS]


__all__ = ['CLAIMS', 'compare_claims', 'resonance_band'] + [c.__name__ for c in CLAIMS]
