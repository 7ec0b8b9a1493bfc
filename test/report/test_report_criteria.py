"""Criteria charts (report/criteria.py) drawn from the criteria study of Kang 1990."""

from flexlink_ros.report import criteria as criteria_report
from flexlink_ros.studies.criteria_check import criteria_data
from png_checks import has_colour, png_size


def test_criteria_section_writes_four_charts_with_every_case(tmp_path):
    data = criteria_data()
    result = criteria_report.plot_criteria(tmp_path / 'out', data=data)
    names = [p.name for p in result['charts']]
    assert names == ['criteria_ratio_vs_crank.png', 'criteria_force_vs_crank.png',
                     'criteria_grid_vs_true.png', 'criteria_input_torque.png']
    for path in result['charts']:
        assert path.parent == tmp_path / 'out'
        width, height = png_size(path)
        assert width > 500 and height > 300
    ratio = result['charts'][0]
    for _, colour in criteria_report.CASE_STYLE.values():
        assert has_colour(ratio, colour, pixels=100), colour
    assert '| original | joint 2 (B) | 1319.45 |' in result['text']
