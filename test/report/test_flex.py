"""Report section of the flexible four-bar (report/flex.py, studies/flex_data), reduced sizes."""

import time

from flexlink_ros.report import flex
from flexlink_ros.studies.flex_data import compute_flex
from flexlink_ros.studies.flex_frequencies import PAPER_RPM
import numpy as np
import pytest

PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'
EXPECTED = ('flex_frequencies_fig7.png', 'flex_frequencies_fig8_10.png',
            'flex_frequencies_fig11_13.png', 'flex_mode_shapes_27deg.png',
            'flex_mode_shapes_123deg.png', 'flex_deflected_linkage.png', 'flex_lever_tip.png',
            'flex_coupler_mid.png', 'flex_coupler_path.png', 'flex_truncation.png')


@pytest.fixture(scope='module')
def section(tmp_path_factory):
    out = tmp_path_factory.mktemp('flex')
    started = time.perf_counter()
    data = compute_flex(quick=True)
    result = flex.plot_flex(out, data=data)
    return out, result, time.perf_counter() - started, data


def test_quick_section_writes_every_chart(section):
    out, result, seconds, _ = section
    assert sorted(p.name for p in result['charts']) == sorted(EXPECTED)
    for path in result['charts']:
        assert path.parent == out
        data = path.read_bytes()
        assert data.startswith(PNG_SIGNATURE) and len(data) > 20_000
    assert seconds < 45.0


def test_quick_section_text_carries_the_numbers(section):
    _, result, _, _ = section
    text = result['text']
    for heading in ('Frozen natural frequencies', 'Mode veering', 'Peak-to-peak',
                    'Modes needed', 'Paper claims'):
        assert heading in text
    for where in ('Fig. 7', 'Figs. 11-13', 'Fig. 20', 'Fig. 21', 'Fig. 22', 'Conclusion 3'):
        assert f'| {where} |' in text
    # every row of a markdown table has as many cells as its header
    cells = None
    for line in text.splitlines():
        if not line.startswith('|'):
            cells = None
            continue
        count = line.count('|')
        cells = count if cells is None else cells
        assert count == cells, line
    # geometric stiffness is always built now: nothing is left out
    assert 'not computed' not in text
    assert 'Computed without geometric stiffness' not in text


def test_claims_follow_from_the_numbers(section):
    data = section[3]
    claims = {c['where'] + c['claim']: c for c in data['claims']}
    fig20 = next(c for key, c in claims.items() if key.startswith('Fig. 20'))
    tip = {key: np.ptp(r.outputs[:, :2], axis=0) for key, r in data['responses'].items()}
    # rigid bearings leave the lever tip to axial strain only: orders of magnitude smaller
    assert all(tip['flexible', rpm].max() > 100 * tip['rigid', rpm].max()
               for rpm in PAPER_RPM)
    assert fig20['verdict'] == 'agree'
    assert {c['verdict'] for c in data['claims']} <= {'agree', 'disagree', 'partly'}


def test_geometric_stiffness_cases_appear(section):
    result = section[1]
    text = result['text']
    assert 'not computed' not in text and 'Computed without' not in text
    for label in ('all flexible, K_G at 30 rad/s', 'rigid crank, K_G at 45 rad/s',
                  'rigid crank, flexible bearings, K_G at 45 rad/s'):
        assert f'| {label} |' in text
    assert '| Conclusion 1 |' in text and '| Figs. 8-9 |' in text
    assert sorted(p.name for p in result['charts']) == sorted(EXPECTED)
