"""
Charts and numbers of the flexible four-bar FE model (Cho, Park & Lee 1992, Sec. 4).

:func:`plot_flex` (the ``flexlink report`` section) draws what
:func:`studies.flex_data.compute_flex` computed (computing it first if not given) and writes:

- ``flex_frequencies_fig7.png``: lowest frozen frequencies vs crank angle, all links flexible,
  no geometric stiffness (Fig. 7), veerings and swaps marked.
- ``flex_frequencies_fig8_10.png``: modes 1-3, all flexible vs rigid crank, with and without
  K_G at 30 and 45 rad/s (Figs. 8-10).
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

The markdown text (:func:`studies.flex_text.report_text`) carries the numbers: frequency
ranges, mode events, peak-to-peak deflections, modes needed for 1 % and 5 %, and the
comparison with each claim of Sec. 4 (:mod:`studies.flex_claims`).
"""

import pathlib

from .flex_modes import plot_fig11_13, plot_fig7, plot_fig8_10, plot_mode_shapes
from .flex_response import plot_coupler_path, plot_deflected_linkage
from .flex_response import plot_point_deflections, plot_truncation
from ..studies.flex_data import compute_flex
from ..studies.flex_frequencies import SHAPE_ANGLES_DEG
from ..studies.flex_text import report_text


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
    mechanism, sweeps = data['mechanism'], data['sweeps']
    charts = [plot_fig7(sweeps['flex'], out / 'flex_frequencies_fig7.png'),
              plot_fig8_10(sweeps, out / 'flex_frequencies_fig8_10.png'),
              plot_fig11_13(sweeps, out / 'flex_frequencies_fig11_13.png')]
    for deg in SHAPE_ANGLES_DEG:
        charts.append(plot_mode_shapes(data['shapes'][deg], deg,
                                       out / f'flex_mode_shapes_{deg:g}deg.png'))
    charts.append(plot_deflected_linkage(data['linkage'], mechanism,
                                         out / 'flex_deflected_linkage.png'))
    charts.append(plot_point_deflections(data['responses'], slice(0, 2),
                                         'Lever tip (upper end of the lever)', 20,
                                         out / 'flex_lever_tip.png'))
    charts.append(plot_point_deflections(data['responses'], slice(2, 4), 'Coupler mid-point',
                                         21, out / 'flex_coupler_mid.png'))
    charts.append(plot_coupler_path(data['responses'], mechanism, out / 'flex_coupler_path.png'))
    charts.append(plot_truncation(data['truncation'], out / 'flex_truncation.png'))
    return {'charts': charts, 'text': report_text(data)}


__all__ = ['plot_flex']
