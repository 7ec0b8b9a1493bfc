"""Charts checked for what a reader sees: names as the node uses them, no overlapping text."""

from flexlink_ros.names import JOINT_NAMES
from flexlink_ros.report import criteria


def test_criteria_charts_name_the_joints_as_the_node_does():
    assert tuple(criteria.JOINT_TITLE) == JOINT_NAMES
    for name, title in criteria.JOINT_TITLE.items():
        assert title.split(' ')[0] == name
    assert [criteria.JOINT_TITLE[j].split('joint ')[-1][0] for j in ('A', 'B', 'O4')] == \
        ['1', '2', '3']
