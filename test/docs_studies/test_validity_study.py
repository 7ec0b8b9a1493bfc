"""The validity sweep's bookkeeping (docs/studies/validity_study.py): separation and the table."""

import validity_study


def _record(rpm, accurate, indicator, load_ratio=0.01, second_ratio=0.5):
    point = {'p2p_error': 0.02 if accurate else 0.2, 'rms_error': 0.01,
             'peer_p2p': [1e-5, 2e-4]}
    return {'rpm': rpm, 'accurate': accurate, 'indicator': indicator, 'load_ratio': load_ratio,
            'second_ratio': second_ratio, 'errors': {'lever_tip': point, 'coupler_mid': point}}


def test_an_indicator_separates_when_accurate_speeds_stay_below_inaccurate_ones():
    records = [_record(250, True, 0.2), _record(300, True, 0.4), _record(400, False, 0.7),
               _record(420, False, 0.5)]
    assert validity_study.separation(records, 'indicator') == {
        'accurate_max': 0.4, 'inaccurate_min': 0.5, 'separates': True}
    records.append(_record(430, False, 0.3))
    assert validity_study.separation(records, 'indicator')['separates'] is False


def test_separation_needs_both_kinds_of_speed():
    only_good = [_record(250, True, 0.2)]
    assert validity_study.separation(only_good, 'indicator') == {
        'accurate_max': 0.2, 'inaccurate_min': None, 'separates': False}


def test_table_has_a_row_per_speed_and_a_verdict_per_candidate():
    records = [_record(250, True, 0.2), _record(400, False, 0.7, load_ratio=0.001)]
    text = validity_study.format_table(records, threshold=0.5)
    lines = text.splitlines()
    assert len(lines) == 1 + len(records) + 3
    assert lines[1].split()[0] == '250' and lines[1].split()[-2:] == ['yes', 'yes']
    assert lines[2].split()[0] == '400' and lines[2].split()[-2:] == ['NO', 'NO']
    assert lines[3].endswith(': separates') and lines[3].startswith('indicator:')
    assert lines[4].startswith('load_ratio:') and lines[4].endswith('does not separate')
